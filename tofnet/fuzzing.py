"""Fuzz targets: every reader, the spec loader and the CLI options, each with the
documented rules its accepted results must satisfy (docs/reliability.md).

A target takes one case (the bytes of a file, or command-line words) and a scratch
folder, and either raises a one-line ``TofnetError`` or returns a result that ``check``
accepts. Shared by the property-based tests (tests/test_fuzz.py) and the long fuzz run
(benchmarks/fuzz.py); ``seeds`` gives valid cases to mutate.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tofnet.errors import TofnetError
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE
from tofnet.fuzzing_checks import (MAX_MESSAGE, Invalid, check_depth, check_events, check_network,  # noqa: F401
                                   check_recording, check_velocity_source, require)

_BASE_EVENTS = b"0.001 1 2 1\n0.002 2 2 0\n0.003 3 2 1\n"


# ---------------------------------------------------------------- targets

def _write(folder: Path, name: str, data: bytes) -> Path:
    path = folder / name
    path.write_bytes(data)
    return path


def _events_txt(data: bytes, folder: Path):
    from tofnet.io.events import read_events_txt
    return read_events_txt(_write(folder, "events.txt", data)), data


def decimal_times_us(data: bytes) -> list[int]:
    """The oracle of the ``events.txt`` parser: each line's ``t`` as µs via Python's
    ``Decimal`` at full precision, rounded half away from zero."""
    import decimal
    context = decimal.Context(prec=60_000, Emax=10**6, Emin=-(10**6), rounding=decimal.ROUND_HALF_UP)
    out = []
    for line in data.split(b"\n"):
        fields = [f for f in re.split(rb"[ \t\r,]+", line) if f]
        if fields and not fields[0].startswith(b"#"):
            value = context.multiply(decimal.Decimal(fields[0].decode()), decimal.Decimal(1_000_000))
            out.append(int(value.to_integral_value(rounding=decimal.ROUND_HALF_UP, context=context)))
    return out


def check_events_txt(result) -> None:
    """The parser's events, and its times equal to the exact decimal oracle."""
    events, data = result
    check_events(events)
    require(events["t"].tolist() == decimal_times_us(data), "times equal the exact decimal value rounded to µs")


def _events_numpy(suffix: str) -> Callable[[bytes, Path], Any]:
    def run(data: bytes, folder: Path):
        from tofnet.io.events import read_events_npy
        return read_events_npy(_write(folder, f"events{suffix}", data))
    return run


def _side_file(name: str) -> Callable[[bytes, Path], Any]:
    def run(data: bytes, folder: Path):
        from tofnet.io import read_recording
        _write(folder, "events.txt", _BASE_EVENTS)
        _write(folder, name, data)
        return read_recording(folder)
    return run


def _samples(data: bytes, folder: Path):
    from tofnet.io.groundtruth import read_velocity_samples
    return read_velocity_samples(_write(folder, "samples.txt", data))


def _depth_file(suffix: str) -> Callable[[bytes, Path], Any]:
    def run(data: bytes, folder: Path):
        from tofnet.io.depth import read_depth
        return read_depth(_write(folder, f"depth{suffix}", data))
    return run


def _spec(data: bytes, folder: Path):
    from tofnet.io.spec import load_spec
    return load_spec(_write(folder, "net.yaml", data)).network


def _cli(words: list[str], folder: Path):
    """``tofnet run`` option parsing and network building (nothing is run)."""
    import contextlib

    from tofnet.cli import build_parser
    from tofnet.cli.run import build_network
    try:
        with contextlib.redirect_stderr(io.StringIO()):  # argparse's usage and one-line error
            args = build_parser().parse_args(["run", str(folder), *words])
    except SystemExit:
        raise TofnetError("argparse refused the options (usage and one error line, exit 2)") from None
    network, compile_options, _, _ = build_network(args, (240, 180))
    if network.sensor_size[0] * network.sensor_size[1] <= 200_000:
        from tofnet.compiler import compile_network
        compile_network(network, **compile_options)
    return network


@dataclass(frozen=True)
class Target:
    name: str
    run: Callable[[Any, Path], Any]
    check: Callable[[Any], None]
    kind: str = "bytes"  # or "words" (command-line options)


TARGETS: dict[str, Target] = {t.name: t for t in (
    Target("events.txt", _events_txt, check_events_txt),
    Target("events.npy", _events_numpy(".npy"), check_events),
    Target("events.npz", _events_numpy(".npz"), check_events),
    Target("calib.txt", _side_file("calib.txt"), check_recording),
    Target("groundtruth.txt", _side_file("groundtruth.txt"), check_recording),
    Target("imu.txt", _side_file("imu.txt"), check_recording),
    Target("sensor_size.txt", _side_file("sensor_size.txt"), check_recording),
    Target("events_depth.npy", _side_file("events_depth.npy"), check_recording),
    Target("velocity samples", _samples, check_velocity_source),
    Target("depth.npz", _depth_file(".npz"), check_depth),
    Target("depth.csv", _depth_file(".csv"), check_depth),
    Target("spec", _spec, check_network),
    Target("cli options", _cli, check_network, kind="words"),
)}


def _format_targets() -> None:
    """Issue 10's formats, read through ``read_recording`` (``tofnet.fuzzing_formats``), and
    specs and plans naming modules (``tofnet.fuzzing_trust``)."""
    from tofnet.fuzzing_formats import FORMAT_FILES, read_format
    from tofnet.fuzzing_trust import trust_targets
    for name in FORMAT_FILES:
        TARGETS[name] = Target(name, read_format(name), check_recording)
    for name, (run, check) in trust_targets().items():
        TARGETS[name] = Target(name, run, check)


_format_targets()


def _storage_targets() -> None:
    """Where a file's data is (HDF5 storage, ROS definitions) and session misuse (``tofnet.fuzzing_storage``)."""
    from tofnet.fuzzing_storage import STORAGE_TARGETS
    for name, (run, check, _, _) in STORAGE_TARGETS.items():
        TARGETS[name] = Target(name, run, check)


_storage_targets()


def _outputs_target() -> None:
    """Issue 27's outputs: command lines whose outputs name inputs (``tofnet.fuzzing_outputs``)."""
    from tofnet.fuzzing_outputs import check_untouched, run_case
    TARGETS["outputs"] = Target("outputs", run_case, check_untouched, kind="words")


_outputs_target()


def outcome(target: Target, case: Any, folder: Path) -> tuple[str, str]:
    """``("error" | "accepted" | "traceback" | "invalid", detail)`` for one case."""
    try:
        result = target.run(case, folder)
    except Invalid as err:  # a target that checks while it runs (outputs)
        return "invalid", str(err)
    except TofnetError as err:
        text = str(err)
        if "\n" in text or len(text) > MAX_MESSAGE:
            return "traceback", f"message of {len(text)} characters over {text.count(chr(10)) + 1} lines"
        return "error", text
    except Exception as err:  # noqa: BLE001 - counting them is the point
        return "traceback", f"{type(err).__name__}: {str(err)[:200]}"
    try:
        target.check(result)
    except Invalid as err:
        return "invalid", str(err)
    return "accepted", ""


# ---------------------------------------------------------------- valid cases to mutate

def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _npz(compress: bool = False, **arrays) -> bytes:
    buffer = io.BytesIO()
    (np.savez_compressed if compress else np.savez)(buffer, **arrays)
    return buffer.getvalue()


def seeds(name: str) -> list:
    """Valid cases of target ``name`` (none for a format whose library is not installed)."""
    events = np.zeros(3, dtype=EVENT_DTYPE)
    events["t"], events["x"], events["y"], events["p"] = [1000, 2000, 3000], [1, 2, 3], [2, 2, 2], [1, 0, 1]
    depth = np.zeros(2, dtype=DEPTH_DTYPE)
    depth["t"], depth["x"], depth["z"], depth["step"] = [3000, 4000], [1, 2], [1.5, 2.5], [1, 2]
    if name == "events.txt":
        return [_BASE_EVENTS, b"# t x y p\r\n1468939993.0674165\t1\t2\t-1\r\n1468939993.9 3 4 1\n"]
    if name == "events.npy":
        return [_npy(events), _npy(np.column_stack([events["t"] * 1e-6, events["x"], events["y"], events["p"]]))]
    if name == "events.npz":
        return [_npz(**{k: events[k] for k in "txyp"}), _npz(True, events=events)]
    if name == "calib.txt":
        return [b"200.0 200.0 119.5 89.5\n", b"# fx fy cx cy k1 k2 p1 p2 k3\n199 198 120 90 0.1 0 0 0 0\n"]
    if name == "groundtruth.txt":
        return [b"0.0 0 0 0 0 0 0 1\n1.0 0.5 0 0 0 0 0 1\n",
                b"0.0 0 0 0 0 0 0.1 1\n0.5 0.1 0.2 0 0 0.1 0 1\n1.0 0.5 0 0 0 0 0 1\n"]
    if name == "imu.txt":
        return [b"0.0 0 0 9.81 0 0 0\n0.001 0 0 9.8 0.01 0 0\n"]
    if name == "sensor_size.txt":
        return [b"240 180\n", b"1280 720\n"]
    if name == "events_depth.npy":
        return [_npy(np.array([1.0, np.nan, 2.5])), _npy(np.array([1.0, 2.0, 3.0], dtype=np.float32))]
    if name == "velocity samples":
        return [b"0.0 0.5 0 0\n1.0 0.5 0.1 0\n", b"# t vx vy vz\n2.5, 0, 0, 1\n"]
    if name == "depth.npz":
        return [_npz(t=depth["t"] * 1e-6, t_us=depth["t"], x=depth["x"], y=depth["y"], z=depth["z"],
                     step=depth["step"], t0_us=np.int64(0), timestep_us=np.int64(1000),
                     latency_steps=np.int64(2), summary_json=np.str_("{}"))]
    if name == "depth.csv":
        return [b"t,x,y,z,step\n0.003000,1,0,1.5,1\n0.004000,2,0,2.5,2\n# end: 2 rows\n"]
    if name == "spec":
        from tofnet.io.spec import default_spec_path
        return [default_spec_path().read_bytes()]
    if name == "cli options":
        return [["--timestep", "1ms"], ["--refractory", "5ms", "--distance", "2", "--sensor-size", "64x48"],
                ["--velocity", "0.5,0,0", "--patch", "30x30", "--counter-bits", "6", "--update-every", "3"]]
    if name == "outputs":
        from tofnet.fuzzing_outputs import SEEDS
        return [list(words) for words in SEEDS]
    from tofnet.fuzzing_formats import FORMAT_FILES, format_seeds
    from tofnet.fuzzing_trust import TRUST_FILES, trust_seeds
    if name in FORMAT_FILES:
        return format_seeds(name)
    from tofnet.fuzzing_storage import STORAGE_TARGETS, storage_seeds
    if name in STORAGE_TARGETS:
        return storage_seeds(name)
    if name in TRUST_FILES:
        return trust_seeds(name)
    raise KeyError(name)


# ---------------------------------------------------------------- mutations

#: Values that broke or might break readers: non-finite, extreme, overlong, unusual bytes.
TOKENS = (
    b"nan", b"inf", b"-inf", b".nan", b".inf", b"1e300", b"-1e300", b"1e-300", b"0", b"-0", b"-1", b"1.5", b"2",
    b"65535", b"65536", b"4294967296", b"9223372036854775807", b"9223372036854775808", b"18446744073709551616",
    b"2305843009213.693952", b"2305843009213.693951", b"-2305843009213.7", b"9.3e12", b"1" + b"0" * 30,
    b"9" * 5000, b"65535.0000000000000000001", b"1.0000000000000000000000001", b"0x10", b"1_000", b"1e", b"e5",
    b"\x00", b"\xff\xfe", b"\xe0\xa5\xa9", b"\n", b"\r\n", b"#", b",", b" ", b"\t", b"'''", b"{", b"}", b"[", b"]",
    b"*a", b"&a", b"!!python/object/apply:os.system", b"!tag", b"<<", b"~", b"null", b"true", b"--", b"100000",
    b"100000x100000", b"0x0", b"65536x65536", b"1ms", b"1e300ms", b"-5ms", b"3601", b"255", b"256", b"30",
    b"this", b"venv.__main__", b"beside_canary", b"os", b"tofnet", b"/**/*.npy", b"../*.npy",  # modules, globs
)

_WORD = re.compile(rb"[A-Za-z0-9_.+\-]+")


def mutate(data: bytes, ops: list[tuple[str, int, int]]) -> bytes:
    """Apply ``(op, position, argument)`` edits to ``data``.

    ``op`` is ``token`` (replace the n-th word with ``TOKENS[argument]``), ``insert``
    (a token at a byte position), ``flip`` (set a byte), ``delete`` (``argument``
    bytes), ``truncate`` or ``duplicate`` (a chunk). Positions wrap around.
    """
    out = bytearray(data)
    for op, position, argument in ops:
        n = max(len(out), 1)
        at = position % (n + 1)
        token = TOKENS[argument % len(TOKENS)]
        if op == "token":
            words = list(_WORD.finditer(bytes(out)))
            if words:
                word = words[position % len(words)]
                out[word.start():word.end()] = token
        elif op == "insert":
            out[at:at] = token
        elif op == "flip" and out:
            out[position % len(out)] = argument % 256
        elif op == "delete":
            del out[at:at + 1 + argument % 64]
        elif op == "truncate":
            del out[at:]
        elif op == "duplicate":
            out[at:at] = out[at:at + 1 + argument % 256]
    return bytes(out)


def mutate_words(words: list[str], ops: list[tuple[str, int, int]]) -> list[str]:
    """Command-line variant of ``mutate``: replace, insert or drop whole words."""
    options = (  # the network options of ``tofnet run``"--timestep", "--refractory", "--distance", "--counter-bits", "--velocity-per", "--update-every",
               "--velocity", "--patch", "--sensor-size", "--spec")
    out = list(words)
    for op, position, argument in ops:
        token = TOKENS[argument % len(TOKENS)].decode("utf-8", "replace")
        at = position % (len(out) + 1)
        if op == "token" and out:
            out[position % len(out)] = token
        elif op == "insert":
            out[at:at] = [options[argument % len(options)], token]
        elif op == "delete" and out:
            del out[position % len(out)]
        elif op == "duplicate" and out:
            out.append(out[position % len(out)])
    return out


OPS = ("token", "insert", "flip", "delete", "truncate", "duplicate")
