"""The time-surface estimator beside the paper's network on every built-in scenario (run by hand, not in CI).

    python benchmarks/time_surface_accuracy.py
    python benchmarks/time_surface_accuracy.py --scenarios slider,all_axes --set 'max_rms_px=0.2'
    python benchmarks/time_surface_accuracy.py --scenarios pan,wobble_slider,tracking_slider --eq7

Each scenario (1 s, seed 0, cached as ``accuracy.py`` does; by default every scenario whose
camera does not turn: ``accuracy.py`` has the turning ones, with eq. 7; here a turning one runs with
eq. 8 unless ``--eq7``, which compensates the rotation in both as ``accuracy.py`` does) runs through the estimator with
its defaults (``TimeSurfaceConfig``, changed by ``--set``) and through the paper's network
(``accuracy.run_network``: 1 ms steps, 8-bit counters, refractory 60 ms), both scored by
``tofnet.eval.metrics.evaluate``. Then the issue's targets: on slider and all_axes a
median relative error at most half the paper network's, coverage of at least 10 % of the
events and a bias (median signed relative error) within +-3 %; no scenario with a larger
median than the paper network's. Text then markdown; progress on stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import ALL_SCENARIOS, fmt, log, markdown_table, print_tables, reproduce  # noqa: E402
from tofnet.sim.scenarios import ROTATION_SCENARIOS  # noqa: E402
from time_surface_runs import paper_metrics, run_time_surface, scenario_recording  # noqa: E402
from time_surface_sweep import add_run_options, parse_assignments  # noqa: E402

TARGET_SCENARIOS = ("slider", "all_axes")
#: The scenarios of this table: the camera does not turn (the estimator computes eq. 8 here).
SCENARIOS = [name for name in ALL_SCENARIOS if name not in ROTATION_SCENARIOS]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--set", default="", help="'name=value;...': estimator defaults to change")
    add_run_options(parser)
    args = parser.parse_args(argv)
    names = [s for s in args.scenarios.split(",") if s]
    cache = Path(args.cache) if args.cache else None
    changes = parse_assignments(args.set)
    header = ["scenario", "events", "estimates", "coverage %", "median rel %", "mean rel %", "bias %",
              "median abs m", "paper: coverage %", "paper: median rel %", "paper: mean rel %", "paper: bias %",
              "median / paper's"]
    rows, verdicts = [], []
    for name in names:
        eq7 = args.eq7 and name in ROTATION_SCENARIOS
        rec = scenario_recording(name, args.duration, cache, args.seed, rotation=eq7)
        m = run_time_surface(rec, rotation=eq7, **changes)
        p = paper_metrics(name, args.duration, cache, args.seed, rotation=eq7)
        ratio = m["median_rel_pct"] / p["median_rel_pct"]
        log(f"  {name:14s} median {m['median_rel_pct']:5.1f} % (paper {p['median_rel_pct']:5.1f} %), "
            f"bias {m['bias_pct']:+5.1f} %, coverage {m['coverage_pct']:5.1f} %")
        rows.append([name + (", eq. 7" if eq7 else ""), fmt(m["events"]), fmt(m["estimates"]), fmt(m["coverage_pct"]), fmt(m["median_rel_pct"]),
                     fmt(m["mean_rel_pct"]), f"{m['bias_pct']:+.1f}", fmt(m["median_abs_m"], 3),
                     fmt(p["coverage_pct"]), fmt(p["median_rel_pct"]), fmt(p["mean_rel_pct"]),
                     f"{p['bias_pct']:+.1f}", fmt(ratio, 2)])
        if name in TARGET_SCENARIOS:
            verdicts.append((f"{name}: median at most half the paper network's", f"{ratio:.2f}", ratio <= 0.5))
            verdicts.append((f"{name}: coverage >= 10 %", f"{m['coverage_pct']:.1f} %", m["coverage_pct"] >= 10))
            verdicts.append((f"{name}: bias within +-3 %", f"{m['bias_pct']:+.1f} %", abs(m["bias_pct"]) <= 3))
        verdicts.append((f"{name}: median not above the paper network's", f"{ratio:.2f}", ratio <= 1.0))
    title = (f"Time-surface estimator (defaults{' + ' + args.set if changes else ''}) beside the paper's network, "
             f"{args.duration:g} s per scenario, seed {args.seed}")
    print_tables(header, rows, title)
    print(markdown_table(["target", "measured", "verdict"],
                         [[what, value, "PASS" if ok else "FAIL"] for what, value, ok in verdicts]) + "\n")
    print(reproduce("time_surface_accuracy.py", [("--scenarios", args.scenarios, ",".join(SCENARIOS)),
                                                 ("--set", f"'{args.set}'", "''"), ("--duration", args.duration, 1.0, "g"),
                                                 ("--seed", args.seed, 0)]) + " --eq7" * args.eq7)
    return 0


if __name__ == "__main__":
    sys.exit(main())
