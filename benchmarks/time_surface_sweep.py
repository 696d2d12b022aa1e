"""One-factor-at-a-time sweeps behind the time-surface estimator's defaults (run by hand, not in CI).

    python benchmarks/time_surface_sweep.py --factors radius,min_points
    python benchmarks/time_surface_sweep.py --factors hold_px --values hold_px=0,2,3 --scenarios slider,room_slider
    python benchmarks/time_surface_sweep.py --base radius=2 --factors window_depth
    python benchmarks/time_surface_sweep.py --factors behind_depth --eq7    # turning scenes with eq. 7

Every built-in scenario (simulated once and cached as ``accuracy.py`` does, 1 s, seed
0) runs through ``TimeSurfaceEstimator`` with the defaults of ``TimeSurfaceConfig``
changed by ``--base``, then each factor of ``--factors`` is varied alone over its values
(``FACTORS``, or ``--values name=v1,v2``). For each value: the median relative error,
bias (median signed relative error) and coverage (estimates per event) of every
scenario, and a summary over the scenarios with realistic pixels (all but ``paper_*``):
mean of the medians and of the means, their average (the criterion docs/accuracy.md
uses for the refractory period), the worst ratio of a scenario's median to the paper
network's (> 1: worse than the paper's network somewhere; over all ten scenarios), the
worst |bias| and the mean coverage, and the CPU speed over all scenarios. The scenarios
whose camera turns (``ROTATION_SCENARIOS``) run with eq. 8 (rotation read as depth) unless
``--eq7``: then both the estimator and the paper's network compensate the rotation as
``accuracy.py`` does (poses at 1 kHz, ω from them). Text then markdown; progress on stderr.
docs/time_surface.md quotes the tables.
"""

from __future__ import annotations

import argparse
import ast
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import ALL_SCENARIOS, default_cache, fmt, log, print_tables, reproduce  # noqa: E402
from time_surface_runs import paper_metrics, run_time_surface, scenario_recording  # noqa: E402
from tofnet.sim.scenarios import ROTATION_SCENARIOS  # noqa: E402

#: The values each factor is swept over (the defaults' value is added when missing).
FACTORS = {
    "model": ["plane", "rows"],
    "radius": [2, 3, 4],
    "min_points": [4, 6, 8, 10, 12],
    "iterations": [1, 2, 3, 5],
    "outlier_px": [0.15, 0.2, 0.25, 0.35, 0.5],
    "max_rms_px": [0.15, 0.2, 0.25, 0.3, 0.4],
    "min_spread": [0.2, 0.35, 0.5, 0.65],
    "window_depth": [2.5, 4.0, 5.0, 7.0, 10.0],
    "ahead_px": [-1.0, -0.5, 0.0, 100.0],
    "refractory_depth": [0.0, 5.0, 10.0, 15.0, 20.0],
    "hold_px": [0.0, 2.0, 3.0, 4.0],
    "turn": [0.0, 0.2],
    "trim_px": [0.0, 0.5],
    "consistency": [0.0, 0.1, 0.2, 0.3],
    "per_pixel": [False, True],
    "behind_depth": [0.0, 5.0, 10.0, 20.0, 40.0],
    "window_px": [0.0, 4.0, 5.0, 6.0, 8.0, 12.0],
}


def parse_value(text: str):
    if text in ("inf", "-inf"):
        return float(text)
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def parse_assignments(text: str) -> dict:
    out = {}
    for item in filter(None, text.split(";")):
        name, _, value = item.partition("=")
        out[name.strip()] = parse_value(value.strip())
    return out


def summary(results: dict, paper: dict, names: list[str]) -> dict:
    """Summary of one configuration's per-scenario metrics (see the module doc)."""
    realistic = [n for n in names if not n.startswith("paper_")] or names
    medians = [results[n]["median_rel_pct"] for n in realistic]
    means = [results[n]["mean_rel_pct"] for n in realistic]
    ratio = max(results[n]["median_rel_pct"] / paper[n]["median_rel_pct"] for n in names)
    events = sum(results[n]["events"] for n in names)
    cpu = sum(results[n]["cpu_s"] for n in names)
    return {"medians": float(np.mean(medians)), "means": float(np.mean(means)),
            "objective": float(np.mean(medians) + np.mean(means)) / 2, "ratio": ratio,
            "bias": max(abs(results[n]["bias_pct"]) for n in realistic),
            "coverage": float(np.mean([results[n]["coverage_pct"] for n in realistic])),
            "mevs": events / cpu / 1e6 if cpu > 0 else float("nan")}


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """``--duration``, ``--seed``, ``--cache`` and ``--eq7``: the options shared with ``time_surface_accuracy.py``."""
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cache", default=str(default_cache()))
    parser.add_argument("--eq7", action="store_true",
                        help="turning scenarios: compensate the rotation (eq. 7, ω from the poses) in both")


def cell(m: dict) -> str:
    return f"{m['median_rel_pct']:.1f} / {m['bias_pct']:+.1f} / {m['coverage_pct']:.1f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--factors", default="", help=f"comma-separated, from: {', '.join(FACTORS)}")
    parser.add_argument("--values", default="", help="'name=v1,v2;other=...' instead of FACTORS' values")
    parser.add_argument("--base", default="", help="'name=value;...': defaults changed for every run")
    parser.add_argument("--scenarios", default=",".join(ALL_SCENARIOS))
    add_run_options(parser)
    args = parser.parse_args(argv)
    names = [s for s in args.scenarios.split(",") if s]
    cache = Path(args.cache) if args.cache else None
    base = parse_assignments(args.base)
    values = {name: [parse_value(v) for v in vs.split(",")] for name, vs in
              (item.split("=", 1) for item in filter(None, args.values.split(";")))}
    factors = [f for f in args.factors.split(",") if f]
    unknown = [f for f in factors if f not in FACTORS and f not in values]
    if unknown:
        parser.error(f"unknown factor(s) {unknown}; known: {', '.join(FACTORS)}")
    start = time.perf_counter()
    eq7 = {n: args.eq7 and n in ROTATION_SCENARIOS for n in names}
    recordings = {n: scenario_recording(n, args.duration, cache, args.seed, rotation=eq7[n]) for n in names}
    paper = {n: paper_metrics(n, args.duration, cache, args.seed, rotation=eq7[n]) for n in names}

    configs = [("defaults" + (f" + {args.base}" if base else ""), base)]
    for factor in factors:
        for v in values.get(factor, FACTORS.get(factor)):
            configs.append((f"{factor}={v}", {**base, factor: v}))

    rows = []
    header = ["configuration", "mean median %", "mean mean %", "objective", "worst median / paper's",
              "worst |bias| %", "mean coverage %", "M ev/s (cpu)"] + [f"{n} med/bias/cov" for n in names]
    seen = {}
    for label, changes in configs:
        key = repr(sorted(changes.items()))
        if key in seen:  # a factor's value equal to the base: same run
            results = seen[key]
        else:
            results = {n: run_time_surface(recordings[n], rotation=eq7[n], **changes) for n in names}
            seen[key] = results
        s = summary(results, paper, names)
        log(f"  {label:28s} objective {s['objective']:5.1f}  worst/paper {s['ratio']:.2f}  "
            f"coverage {s['coverage']:4.1f} %  {s['mevs']:.1f} M ev/s")
        row = [label, fmt(s["medians"]), fmt(s["means"]), fmt(s["objective"]), fmt(s["ratio"], 2), fmt(s["bias"]),
               fmt(s["coverage"]), fmt(s["mevs"])] + [cell(results[n]) for n in names]
        rows.append(row)
    paper_row = ["paper's network", "", "", "", "1.00", "", "", ""] + [cell(paper[n]) for n in names]
    print_tables(header, rows + [paper_row], f"Time-surface sweep: {args.duration:g} s per scenario, seed {args.seed}"
                 f"{'; turning scenarios with eq. 7' if any(eq7.values()) else ''}; cells: median rel % / bias % / "
                 f"coverage %; summary over the scenarios with realistic pixels (ratio over all); "
                 f"{time.perf_counter() - start:.0f} s")
    quoted = [(flag, f"'{value}'", "''") for flag, value in (("--factors", args.factors), ("--values", args.values),
                                                              ("--base", args.base))]
    print(reproduce("time_surface_sweep.py", quoted + [("--scenarios", args.scenarios, ",".join(ALL_SCENARIOS)),
                                                       ("--duration", args.duration, 1.0, "g"), ("--seed", args.seed, 0)])
          + " --eq7" * args.eq7)
    return 0


if __name__ == "__main__":
    sys.exit(main())
