"""Instructions per event of the time-surface kernel, counted by valgrind (run by hand, not in CI).

    python benchmarks/time_surface_instructions.py                       # under a minute
    python benchmarks/time_surface_instructions.py --streams edges:1e6 --set 'iterations=3'

Timings on a shared machine move by several per cent from one minute to the next; an
instruction count does not. For each stream (``benchmarks/streams.py``, the first
``--events`` events) the estimator is fed once under ``valgrind --tool=callgrind`` with
instrumentation switched on around ``feed`` alone (``--instr-atstart=no``, then
``callgrind_control -i on`` / ``off`` from inside: Python's start-up, the stream's loading
and the kernel's compilation, or its loading from numba's cache by a first small feed, are
not counted). The kernel is compiled into numba's cache by a plain run first. Prints instructions and mispredicted branches (callgrind's simulated
predictor) per event: a figure for comparing two versions of the kernel or two
configurations on one machine, not a time. Needs valgrind (``callgrind_control`` with it).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import print_tables  # noqa: E402
from time_surface_speed import estimator_for, recording_of  # noqa: E402
from time_surface_sweep import parse_assignments  # noqa: E402


def feed_once(spec: str, events: int, changes: dict, toggle: bool) -> None:
    """Feed the first ``events`` of ``spec`` to a fresh estimator, counting only the feed when ``toggle``."""
    recording = recording_of(spec)
    chunk = recording.events[:events].copy()
    warm, rows = estimator_for(recording, **changes)
    warm.feed(chunk[:1000], rows)  # loads the kernel from numba's cache here, not inside the count
    estimator, rows = estimator_for(recording, **changes)
    switch = ["callgrind_control", "-i"]
    if toggle:
        subprocess.run([*switch, "on", str(os.getpid())], check=True, capture_output=True)
    estimator.feed(chunk, rows)
    if toggle:
        subprocess.run([*switch, "off", str(os.getpid())], check=True, capture_output=True)


def counted(spec: str, events: int, assignments: str) -> tuple[float, float]:
    """(instructions, mispredicted branches) per event of one feed under callgrind."""
    script = str(Path(__file__).resolve())
    common = [script, "--inner", spec, "--events", str(events), "--set", assignments]
    subprocess.run([sys.executable, *common, "--no-toggle"], check=True)  # compile into numba's cache
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", "--branch-sim=yes",
                        f"--callgrind-out-file={out}", sys.executable, *common], check=True, capture_output=True)
        totals = next(line for line in out.read_text().splitlines() if line.startswith("totals:"))
    ir, _, conditional_missed, _, indirect_missed = (int(v) for v in totals.split()[1:6])
    return ir / events, (conditional_missed + indirect_missed) / events


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--streams", default="uniform:1e6,edges:1e6,slider")
    parser.add_argument("--events", type=int, default=200_000, help="events fed per stream (default 200000)")
    parser.add_argument("--set", default="", help="'name=value;...': estimator parameters changed")
    parser.add_argument("--inner", default="", help=argparse.SUPPRESS)
    parser.add_argument("--no-toggle", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    changes = parse_assignments(args.set)
    if args.inner:
        feed_once(args.inner, args.events, changes, toggle=not args.no_toggle)
        return 0
    missing = [tool for tool in ("valgrind", "callgrind_control") if shutil.which(tool) is None]
    if missing:
        print(f"time_surface_instructions: {' and '.join(missing)} not found; install valgrind", file=sys.stderr)
        return 2
    header = ["stream", "events", "instructions per event", "mispredicted branches per event"]
    rows = []
    for spec in (s for s in args.streams.split(",") if s):
        print(f"  {spec} ...", file=sys.stderr, flush=True)
        ir, missed = counted(spec, args.events, args.set)
        rows.append([spec, f"{args.events:,}", f"{ir:.1f}", f"{missed:.2f}"])
    print_tables(header, rows, f"Time-surface kernel under callgrind ({args.set or 'defaults'})", blank_after=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
