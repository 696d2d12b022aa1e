"""The refractory sweep behind ``DEFAULT_REFRACTORY`` (run by hand, not in CI).

    python benchmarks/refractory_sweep.py
    python benchmarks/refractory_sweep.py --values 0,5,20 --scenarios slider --duration 0.5

For every built-in scenario (simulated once, cached as in ``accuracy.py``) and every
refractory period, runs the paper's network (1 ms steps, 8-bit counters) and prints
median and mean relative error, bias (median signed relative error) and coverage,
then a summary over the scenarios with realistic pixels (all but ``paper_*``): the
mean of the per-scenario medians and of the means, their average (the criterion
docs/accuracy.md uses), the worst regret (points above the scenario's best period),
the worst |bias| and the coverage. Text and markdown. Progress on stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import (ALL_SCENARIOS, default_backend, default_cache, fmt, log, markdown_table, parse_size,  # noqa: E402
                      recording_for, reproduce, run_network, scenario_config, text_table)
from tofnet.processes.input import DEFAULT_REFRACTORY  # noqa: E402

VALUES_MS = "0,1,2,5,10,15,20,30,40,50,60,75,100"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--values", default=VALUES_MS, help=f"refractory periods in ms (default {VALUES_MS})")
    parser.add_argument("--scenarios", default=",".join(ALL_SCENARIOS))
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", default="240x180")
    parser.add_argument("--backend", default=None)
    parser.add_argument("--per-polarity", action="store_true", help="refractory per polarity (not the default)")
    parser.add_argument("--cache", default=str(default_cache()))
    args = parser.parse_args(argv)
    values = [v for v in args.values.split(",") if v]
    names = [s for s in args.scenarios.split(",") if s]
    backend = args.backend or default_backend()
    cache = Path(args.cache) if args.cache else None
    size = parse_size(args.size)
    log(f"refractory sweep: {names} x {values} ms, {args.duration:g} s, seed {args.seed}, backend {backend}")

    results: dict[tuple[str, str], dict] = {}
    for name in names:
        rec = recording_for(scenario_config(name, args.duration, size), args.seed, cache)
        for v in values:
            r = run_network(rec, backend=backend, refractory=f"{v}ms", per_polarity=args.per_polarity)
            m = r.metrics()
            results[name, v] = m
            log(f"  {name:12s} {v:>3s} ms: median {m['median_rel_pct']:5.1f} %  mean {m['mean_rel_pct']:5.1f} %  "
                f"bias {m['bias_pct']:+6.1f} %  coverage {m['coverage_pct']:5.1f} %")

    header = ["scenario", "refractory ms", "median rel %", "mean rel %", "bias %", "coverage %", "estimates"]
    rows = []
    for name in names:
        for v in values:
            m = results[name, v]
            rows.append([name, v, fmt(m["median_rel_pct"]), fmt(m["mean_rel_pct"]), f"{m['bias_pct']:+.1f}",
                         fmt(m["coverage_pct"]), fmt(m["estimates"])])
    # The choice: scenarios with the simulator's default (realistic) pixels; paper_* have ESIM's ideal ones.
    realistic = [n for n in names if not n.startswith("paper_")] or names
    best_median = {n: min(results[n, v]["median_rel_pct"] for v in values) for n in realistic}
    best_mean = {n: min(results[n, v]["mean_rel_pct"] for v in values) for n in realistic}
    summary_header = ["refractory ms", "mean of medians %", "mean of means %", "(medians+means)/2 %",
                      "worst median regret", "worst mean regret", "worst abs bias %", "mean coverage %"]
    summary = []
    objective = {}
    for v in values:
        ms = [results[n, v] for n in realistic]
        medians = np.mean([m["median_rel_pct"] for m in ms])
        means = np.mean([m["mean_rel_pct"] for m in ms])
        objective[v] = (medians + means) / 2
        summary.append([v, fmt(medians), fmt(means), fmt(objective[v]),
                        fmt(max(results[n, v]["median_rel_pct"] - best_median[n] for n in realistic)),
                        fmt(max(results[n, v]["mean_rel_pct"] - best_mean[n] for n in realistic)),
                        fmt(max(abs(m["bias_pct"]) for m in ms)), fmt(np.mean([m["coverage_pct"] for m in ms]))])
    best = min(values, key=lambda v: objective[v])
    matrix_header = ["refractory ms"] + list(names)
    matrices = {}
    for key, label, signed in (("median_rel_pct", "Median relative error, %", False),
                               ("mean_rel_pct", "Mean relative error, %", False),
                               ("bias_pct", "Bias (median signed relative error), %", True),
                               ("coverage_pct", "Coverage (estimates per input event), %", False)):
        matrices[label] = [[v] + [f"{results[n, v][key]:+.1f}" if signed else fmt(results[n, v][key])
                                  for n in names] for v in values]

    title = (f"Refractory sweep: {args.duration:g} s per scenario, seed {args.seed}, {size[0]}x{size[1]}, 1 ms steps, "
             f"8-bit counters, backend {backend}{', per polarity' if args.per_polarity else ''}; "
             f"current default {DEFAULT_REFRACTORY}")
    print(title)
    print()
    print(text_table(header, rows))
    print()
    print(f"Summary over the scenarios with realistic pixels ({', '.join(realistic)}); regret: points above "
          f"the scenario's best over the sweep")
    print(text_table(summary_header, summary))
    print(f"lowest (medians+means)/2: {best} ms")
    print()
    for label, rows_ in matrices.items():
        print(label)
        print(text_table(matrix_header, rows_))
        print()
    print(markdown_table(summary_header, summary))
    print()
    for label, rows_ in matrices.items():
        print(f"{label}:\n")
        print(markdown_table(matrix_header, rows_))
        print()
    print(markdown_table(header, rows))
    print()
    cmd = reproduce("refractory_sweep.py", [("--values", args.values, VALUES_MS),
                                            ("--scenarios", args.scenarios, ",".join(ALL_SCENARIOS)),
                                            ("--duration", args.duration, 1.0), ("--seed", args.seed, 0),
                                            ("--size", args.size, "240x180")])
    print(cmd + " --per-polarity" * args.per_polarity + (f" --backend {args.backend}" if args.backend else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
