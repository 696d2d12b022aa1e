"""Where the time-surface estimator's time goes, stage by stage (run by hand, not in CI).

    python benchmarks/time_surface_stages.py                  # about 1 min
    python benchmarks/time_surface_stages.py --streams slider,uniform:1e6 --rounds 5

The kernel is not instrumented: each stage is cut off by a parameter, on the same stream
(``benchmarks/streams.py``, 240x180, 1 s, one packet, CPU time, best of ``--rounds``):

- *no fit*: ``behind_depth`` 1 µm, so almost every first event ends ``nothing_behind``
  before its square is read: the event loop, the first-event rule and the check behind;
- *gather*: ``min_points`` 999: the square is read, then the event is counted
  ``too_few_points`` (fewer gathered points than ``min_points``: no sums, no fit; before
  that early exit this stage also added the lines' sums);
- *one pass*: ``iterations`` 0: one residual pass, no outlier dropped;
- *defaults*: up to ``iterations`` (2) more passes, one dropped point each.

The stages change the holds a little (a rejected fit sets none), so the share of fitted
events differs by a few points between rows; the per-fit costs divide by each row's own
count. Text then markdown.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import fmt, log, print_tables  # noqa: E402
from performance import machine  # noqa: E402
from time_surface_speed import estimator_for, recording_of  # noqa: E402

STAGES = (("no fit", {"behind_depth": 1e-6}), ("gather", {"min_points": 999}), ("one pass", {"iterations": 0}),
          ("defaults", {}))
NOT_FITTED = ("out_of_bounds", "before_t0", "burst", "no_motion", "nothing_behind")


def timed(recording, changes: dict, rounds: int) -> tuple[float, int]:
    """Best CPU seconds of ``rounds`` one-packet runs, and the events fitted (a square read)."""
    best, fitted = float("inf"), 0
    for _ in range(rounds):
        estimator, rows = estimator_for(recording, **changes)
        gc.collect()
        started = time.process_time()
        estimator.feed(recording.events, rows)
        best = min(best, time.process_time() - started)
        fitted = sum(v for k, v in estimator.counts.items() if k not in NOT_FITTED)
    return best, fitted


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--streams", default="slider,uniform:1e6,edges:1e6,edges:1e7")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    header = ["stream", "stage", "ns per event", "M ev/s", "fitted % of events", "ns per fitted event over 'no fit'"]
    rows = []
    for spec in (s for s in args.streams.split(",") if s):
        recording = recording_of(spec)
        timed(recording, {}, 1)  # compile and warm up
        n = len(recording.events)
        base = None
        for name, changes in STAGES:
            log(f"{spec}: {name}")
            cpu, fitted = timed(recording, changes, args.rounds)
            base = cpu if base is None else base
            extra = fmt((cpu - base) / fitted * 1e9, 0) if fitted and name != "no fit" else "-"
            rows.append([spec, name, fmt(cpu / n * 1e9, 1), fmt(n / cpu / 1e6), fmt(100 * fitted / n), extra])
    print_tables(header, rows, f"Time-surface estimator by stage, best of {args.rounds} rounds, CPU time; {machine()}")
    print("reproduce: python benchmarks/time_surface_stages.py" +
          (f" --streams {args.streams}" if args.streams != parser.get_default("streams") else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
