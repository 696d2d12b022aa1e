"""The paper network's speed now against an earlier commit, measured in one run.

    python benchmarks/versions.py                 # against e2dc198 (before the open process graph)
    python benchmarks/versions.py --base v0.1 --rounds 7
    python benchmarks/versions.py --instructions  # CPU instructions under valgrind: the machine's load does not count
    python benchmarks/versions.py --instructions --cache-sim   # and cache misses (L1i, L1d), about 2x slower

Checks the base commit out into a temporary git worktree, writes the same streams to
disk once (benchmarks/streams.py: the slider and fast_slider scenes, uniform and moving
edges at 1 M and 20 M events/s, 240x180), and then times both code trees in alternating
subprocesses, ``--rounds`` times each (a slow spell of a shared machine then hits both):
the ``fixed`` backend's ``run`` on each whole stream (CPU time) and the stream fed in
1 ms packets (mean µs per packet). Best round per tree; the ratio is now / base.

``--instructions`` counts instead the instructions one ``run`` executes (valgrind's
callgrind, the difference between 1 and 1 + ``--runs`` runs in one process, so imports and
set-up cancel out), on the slider scene and the edges stream at 1 M events/s, each by
``run`` and fed in 1 ms packets: a measure that a loaded machine does not disturb
(instructions are not time: memory stalls are not counted). Both trees compile for a
generic x86-64 CPU (``NUMBA_CPU_NAME=generic``) in caches of their own, warmed outside
valgrind, with one BLAS thread. About 20 minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import streams

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_BASE = "e2dc198"  # the last commit before the open process graph (issue 9)
STREAMS = (("slider", None), ("fast_slider", None), ("uniform", 1e6), ("edges", 1e6), ("uniform", 20e6),
           ("edges", 20e6))
INTRINSICS = (199.1, 198.5, 119.5, 89.5)
VELOCITY = (-0.5, 0.05, 0.1)  # m/s; a constant velocity keeps both trees on the same input

TIMER = r'''
import gc, json, sys, time
import numpy as np
from tofnet.backends.event_driven import FixedBackend
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording
from tofnet.networks import depth_network

files, intrinsics, velocity = json.loads(sys.argv[1]), Intrinsics(*json.loads(sys.argv[2])), tuple(json.loads(sys.argv[3]))
out = {}
for name, path in files.items():
    events = np.load(path)
    recording = Recording(events, intrinsics=intrinsics, trajectory=ConstantVelocity(velocity), sensor_size=(240, 180))
    net = depth_network((240, 180), velocity={"source": "constant", "velocity": list(velocity)})
    FixedBackend().run(net, recording)  # compile or load the cache
    gc.collect()
    started = time.process_time()
    FixedBackend().run(net, recording)
    run_s = time.process_time() - started
    t = events["t"]
    bounds = np.searchsorted(t, np.arange(int(t[0]), int(t[-1]) + 1001, 1000))
    stream = FixedBackend().open_stream(net, intrinsics=intrinsics, velocity_source=ConstantVelocity(velocity),
                                        t0_us=int(t[0]))
    parts = [events[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]
    clock = time.perf_counter
    started = clock()
    for part in parts:
        stream.feed(part)
    out[name] = {"events": len(events), "run_s": run_s, "packet_us": (clock() - started) / len(parts) * 1e6}
print(json.dumps(out))
'''


COUNTER = r'''
import sys
import numpy as np
from tofnet.backends.event_driven import FixedBackend
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording
from tofnet.networks import depth_network

path, runs, packets = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "packets"
intrinsics, velocity = Intrinsics(199.1, 198.5, 119.5, 89.5), (-0.5, 0.05, 0.1)
events = np.load(path)
recording = Recording(events, intrinsics=intrinsics, trajectory=ConstantVelocity(velocity), sensor_size=(240, 180))
net = depth_network((240, 180), velocity={"source": "constant", "velocity": list(velocity)})
t = events["t"]
bounds = np.searchsorted(t, np.arange(int(t[0]), int(t[-1]) + 1001, 1000))
parts = [events[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]
for _ in range(runs):
    if packets:
        stream = FixedBackend().open_stream(net, intrinsics=intrinsics, velocity_source=ConstantVelocity(velocity),
                                            t0_us=int(t[0]))
        for part in parts:
            stream.feed(part)
    else:
        FixedBackend().run(net, recording)
'''
#: (stream, how it is fed): ``run`` on the whole stream, or ``feed`` of 1 ms packets
INSTRUCTION_STREAMS = (("slider", "run"), ("edges 1M", "run"), ("slider", "packets"), ("edges 1M", "packets"))


def count_instructions(tree: Path, script: Path, path: str, runs: int, cache: Path, how: str,
                       cache_sim: bool) -> np.ndarray:
    """Callgrind's ``Collected`` counts of ``runs`` fused runs (or packet streams) plus the process's
    start: instructions, and with ``cache_sim`` also Dr Dw I1mr D1mr D1mw ILmr DLmr DLmw."""
    import re
    # one BLAS thread: idle BLAS threads spin, and their instructions would depend on timing; one string
    # hash seed: a random one moves the start-up's dict probes by millions of instructions per process
    env = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(cache),
           "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
    subprocess.run([sys.executable, str(script), path, "1", how], env=env, check=True, capture_output=True, cwd=tree)
    done = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                           *(["--cache-sim=yes"] if cache_sim else []), sys.executable,
                           str(script), path, str(runs), how], env=env, capture_output=True, text=True, cwd=tree)
    found = re.search(r"Collected : ([\d ]+)", done.stderr)
    if done.returncode or not found:
        raise SystemExit(f"valgrind on {tree} failed:\n{done.stderr[-3000:]}")
    return np.array([int(v) for v in found.group(1).split()], dtype=np.float64)


def instructions(base_tree: Path, tmp: Path, files: dict[str, str], extra_runs: int, cache_sim: bool) -> None:
    script = tmp / "counter.py"
    script.write_text(COUNTER)
    rows = []
    for name, how in INSTRUCTION_STREAMS:
        per_run = {}
        for label, tree in (("base", base_tree), ("now", ROOT)):
            print(f"{name} ({how}): {label}", flush=True)
            one = count_instructions(tree, script, files[name], 1, tmp / f"cache-{label}", how, cache_sim)
            more = count_instructions(tree, script, files[name], 1 + extra_runs, tmp / f"cache-{label}", how,
                                      cache_sim)
            per_run[label] = (more - one) / extra_runs
        events = len(np.load(files[name], mmap_mode="r"))
        rows.append((f"{name}, {'1 ms packets' if how == 'packets' else 'run'}", events, per_run["base"],
                     per_run["now"]))
    print(f"\n## Instructions per pass over a stream of the paper's network (fixed, fused), base vs now; "
          f"difference of 1 and {1 + extra_runs} passes under callgrind, generic x86-64 code\n")
    misses = " | base / now L1i misses (k) | base / now L1d read misses (k)" if cache_sim else ""
    print(f"| stream, fed by | events | base M instructions | now M instructions | per event base / now "
          f"| now / base{misses} |")
    print("| --- " * (6 + 2 * cache_sim) + "|")
    for name, events, base, now in rows:
        extra = (f" | {base[3] / 1e3:.0f} / {now[3] / 1e3:.0f} | {base[4] / 1e3:.0f} / {now[4] / 1e3:.0f}"
                 if cache_sim else "")
        print(f"| {name} | {events:,} | {base[0] / 1e6:.1f} | {now[0] / 1e6:.1f} | {base[0] / events:.0f} / "
              f"{now[0] / events:.0f} | {now[0] / base[0]:.3f}{extra} |")


def write_streams(folder: Path, duration: float) -> dict[str, str]:
    files = {}
    for kind, rate in STREAMS:
        name = kind if rate is None else f"{kind} {rate / 1e6:g}M"
        recording = streams.scenario(kind, duration, print) if rate is None else \
            getattr(streams, kind)((240, 180), rate, duration)
        path = folder / (name.replace(" ", "_") + ".npy")
        np.save(path, recording.events)
        files[name] = str(path)
    return files


def time_tree(tree: Path, script: Path, files: dict[str, str]) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, str(script), json.dumps(files), json.dumps(INTRINSICS),
                           json.dumps(VELOCITY)], env=env, capture_output=True, text=True, cwd=tree)
    if done.returncode:
        raise SystemExit(f"timing {tree} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default=DEFAULT_BASE, help=f"git commit to compare with (default {DEFAULT_BASE})")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--duration", type=float, default=1.0, help="seconds per stream")
    parser.add_argument("--instructions", action="store_true", help="count instructions under valgrind instead")
    parser.add_argument("--runs", type=int, default=5, help="--instructions: runs counted beyond the first")
    parser.add_argument("--cache-sim", action="store_true",
                        help="--instructions: also simulate the caches (L1i, L1d misses; about 2x slower)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base_tree = tmp / "base"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base_tree), args.base],
                       check=True, capture_output=True)
        try:
            files = write_streams(tmp, args.duration)
            if args.instructions:
                instructions(base_tree, tmp, files, args.runs, args.cache_sim)
                return
            script = tmp / "timer.py"
            script.write_text(TIMER)
            best: dict[str, dict] = {"base": {}, "now": {}}
            for r in range(args.rounds):
                for label, tree in (("base", base_tree), ("now", ROOT)):
                    print(f"round {r + 1}/{args.rounds}: {label}", flush=True)
                    for name, m in time_tree(tree, script, files).items():
                        kept = best[label].setdefault(name, dict(m))
                        kept["run_s"] = min(kept["run_s"], m["run_s"])
                        kept["packet_us"] = min(kept["packet_us"], m["packet_us"])
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base_tree)], check=False)
    print(f"\n## The paper's network (fixed backend, fused), {args.base} vs now; best of {args.rounds} rounds, "
          f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}\n")
    print("| stream | events | base M ev/s | now M ev/s | now / base | base µs per 1 ms packet | now | now / base |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in best["now"]:
        b, n = best["base"][name], best["now"][name]
        print(f"| {name} | {n['events']:,} | {b['events'] / b['run_s'] / 1e6:.1f} | {n['events'] / n['run_s'] / 1e6:.1f} "
              f"| {n['run_s'] / b['run_s']:.2f}x time | {b['packet_us']:.1f} | {n['packet_us']:.1f} "
              f"| {n['packet_us'] / b['packet_us']:.2f}x |")


if __name__ == "__main__":
    main()
