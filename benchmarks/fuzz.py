"""Long fuzz run over every reader, the spec loader and the CLI options (issue 11).

    python benchmarks/fuzz.py                 # 20,000 cases, seed 0 (a few minutes)
    python benchmarks/fuzz.py --cases 2000 --target spec --show 5

Each case is a valid file (``tofnet.fuzzing.seeds``) with 1-4 random edits
(``tofnet.fuzzing.mutate``: hostile tokens, byte flips, cuts, duplications) or, for
numpy formats, a random array of random dtype, shape and extreme values (for the HDF5 storage
and ROS definition recipes, every option drawn at random). A case ends
in one of: a clean error (one-line ``TofnetError``), accepted (the result satisfies
the documented rules, ``Target.check``), a traceback (any other exception, or a
multi-line or overlong message), accepted-but-invalid, or a hang (longer than
``--timeout`` seconds). The process runs under a 6 GB address-space limit, so a
memory blow-up shows as a traceback instead of taking the machine down. Prints one
row per target and the totals; exit status 1 when anything but clean errors and valid
results occurred. Failing cases are written to ``--save`` for reproduction.
"""

from __future__ import annotations

import argparse
import warnings
import random
import resource
import signal
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from tofnet.fuzzing import OPS, TARGETS, TOKENS, _npy, _npz, mutate, mutate_words, outcome, seeds
from tofnet.fuzzing_storage import STORAGE_TARGETS, random_recipe
from tofnet.fuzzing_trust import TRUST_FILES, trust_case

NUMPY_TARGETS = {"events.npy", "events.npz", "events_depth.npy", "depth.npz", "hdf5"}
DTYPES = ("<i1", "<u1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", ">i8", "<f2", "<f4", "<f8", ">f8", "?", "<c16",
          "<U3", "S2", "<M8[us]")
SPECIAL = (0, 1, -1, 2**15, 2**16 - 1, 2**31, 2**53 + 1, 2**61, 2**62, 2**63 - 1, -(2**63), 2**64 - 1,
           0.5, 1e-300, 1e300, float("nan"), float("inf"), float("-inf"), 9.3e12, 2.3e12)


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang()


def random_array(rng: random.Random, n: int, dtype: str | None = None) -> np.ndarray:
    """A 1-D array of a random dtype holding ordinary and extreme values."""
    dtype = np.dtype(dtype or rng.choice(DTYPES))
    values = [rng.choice(SPECIAL) if rng.random() < 0.3 else rng.randint(0, 300) for _ in range(n)]
    if rng.random() < 0.7:
        values.sort(key=lambda v: (v != v, v))
    out = np.zeros(n, dtype=dtype)
    for i, v in enumerate(values):
        try:
            with np.errstate(all="ignore"):
                out[i] = v
        except (OverflowError, ValueError, TypeError):
            pass  # a value the dtype cannot hold: keep 0
    return out


def numpy_case(rng: random.Random, name: str) -> bytes:
    n = rng.choice((0, 1, 3, 3, 3, 7))
    columns = {k: random_array(rng, n if rng.random() < 0.9 else n + 1) for k in "txyp"}
    if name == "events_depth.npy":
        return _npy(random_array(rng, 3 if rng.random() < 0.8 else n))
    if name == "events.npy":
        if rng.random() < 0.5:
            dtype = [(k, columns[k].dtype) for k in ("t", "x", "y", "p")[: rng.choice((3, 4, 4))]]
            out = np.zeros(n, dtype=dtype)
            for k, _ in dtype:
                out[k] = columns[k][:n] if len(columns[k]) >= n else 0
            return _npy(out)
        width = rng.choice((3, 4, 4, 5))
        return _npy(random_array(rng, n * width, rng.choice(DTYPES)).reshape(n, width))
    if name == "events.npz":
        return _npz(rng.random() < 0.5, **columns)
    if name == "hdf5":  # the DSEC layout's datasets, of random dtypes and values
        arrays = {f"events.{k}": v for k, v in columns.items()}
        for key, size in (("t_offset", 1), ("calib.resolution", 2), ("calib.intrinsics", 4), ("imu.t", n)):
            if rng.random() < 0.5:
                arrays[key] = random_array(rng, size)
        return _npz(False, **arrays)
    arrays = {k: random_array(rng, n) for k in ("t", "t_us", "x", "y", "z", "step")}
    arrays.update({k: random_array(rng, 1)[0] for k in ("t0_us", "timestep_us", "latency_steps")})
    if rng.random() < 0.5:
        arrays["summary_json"] = np.str_(rng.choice(("{}", "[" * 5000, '{"a": 1}', "nan", "")))
    return _npz(rng.random() < 0.5, **arrays)


def make_case(rng: random.Random, name: str):
    target = TARGETS[name]
    ops = [(rng.choice(OPS), rng.randrange(1 << 30), rng.randrange(len(TOKENS) * 8))
           for _ in range(rng.randint(1, 4))]
    if target.kind == "words":
        return mutate_words(rng.choice(seeds(name)), ops)
    if name in STORAGE_TARGETS and rng.random() < 0.5:  # every option at random, then maybe edited
        case = random_recipe(rng, name)
        return mutate(case, ops) if rng.random() < 0.3 else case
    if name in TRUST_FILES and rng.random() < 0.5:
        case = trust_case(rng, name)
        return mutate(case, ops) if rng.random() < 0.3 else case
    if name in NUMPY_TARGETS and rng.random() < 0.4:
        case = numpy_case(rng, name)
        return mutate(case, ops) if rng.random() < 0.3 else case
    return mutate(rng.choice(seeds(name)), ops)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds before a case counts as a hang")
    parser.add_argument("--target", action="append", choices=tuple(TARGETS))
    parser.add_argument("--show", type=int, default=3, help="examples printed per bad outcome")
    parser.add_argument("--save", type=Path, help="folder to write failing cases to")
    args = parser.parse_args(argv)

    limit = 6 * 2**30
    resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))
    signal.signal(signal.SIGALRM, _alarm)
    warnings.simplefilter("ignore")  # numpy's casting warnings while building cases
    names = args.target or list(TARGETS)
    rng = random.Random(args.seed)
    counts = {name: Counter() for name in names}
    examples: dict[str, list] = {}
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        folders = {name: Path(scratch) / f"t{i}" for i, name in enumerate(names)}
        for folder in folders.values():
            folder.mkdir()
        for i in range(args.cases):
            name = names[i % len(names)]
            case = make_case(rng, name)
            begun = time.perf_counter()
            signal.setitimer(signal.ITIMER_REAL, args.timeout)
            try:
                kind, detail = outcome(TARGETS[name], case, folders[name])
            except Hang:
                kind, detail = "hang", f"interrupted after {args.timeout} s"
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            if kind != "hang" and time.perf_counter() - begun > args.timeout:
                kind, detail = "hang", f"took {time.perf_counter() - begun:.1f} s"
            counts[name][kind] += 1
            if kind in ("traceback", "invalid", "hang"):
                examples.setdefault(kind, []).append((name, case, detail))
                if args.save:
                    args.save.mkdir(parents=True, exist_ok=True)
                    data = case if isinstance(case, bytes) else "\n".join(case).encode()
                    (args.save / f"{kind}-{i}-{name.replace(' ', '_')}").write_bytes(data)
            if (i + 1) % 2000 == 0:
                print(f"  {i + 1:,} cases, {time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)
    elapsed = time.perf_counter() - started

    header = f"{'target':18s} {'cases':>7s} {'clean errors':>13s} {'accepted':>9s} {'tracebacks':>11s} " \
             f"{'hangs':>6s} {'accepted-but-invalid':>21s}"
    print(header)
    total = Counter()
    for name in names:
        c = counts[name]
        total.update(c)
        print(f"{name:18s} {sum(c.values()):7,d} {c['error']:13,d} {c['accepted']:9,d} {c['traceback']:11,d} "
              f"{c['hang']:6,d} {c['invalid']:21,d}")
    print(f"{'total':18s} {sum(total.values()):7,d} {total['error']:13,d} {total['accepted']:9,d} "
          f"{total['traceback']:11,d} {total['hang']:6,d} {total['invalid']:21,d}")
    print(f"{elapsed:.0f} s, seed {args.seed}, timeout {args.timeout:g} s per case")
    for kind, found in examples.items():
        for name, case, detail in found[: args.show]:
            print(f"{kind} in {name}: {detail}\n    case: {repr(case)[:300]}")
    return 1 if any(total[k] for k in ("traceback", "invalid", "hang")) else 0


if __name__ == "__main__":
    sys.exit(main())
