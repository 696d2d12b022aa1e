"""Where the time-surface estimator's negative bias comes from (run by hand, not in CI).

    python benchmarks/time_surface_bias.py                  # every section, about 5 min on 2 busy cores
    python benchmarks/time_surface_bias.py --only steps,truncation

A plain plane fit over the recent first events of a neighbourhood (the issue's prototype)
under-estimates depth by a few to tens of percent. Sections (markdown tables; quoted in
docs/time_surface.md):

- ``steps``: from that plain fit to the defaults, one change at a time, on slider,
  all_axes, room_slider and paper_slider (1 s): median relative error, bias (median
  signed relative error) and coverage, with the simulator's ground truth and with the
  nearer surface's depth at occluding contours (the edge that moved is the occluding one).
- ``time``: the defaults' bias by time since the motion started, per scenario.
- ``truncation``: the mechanism on synthetic data: a plane ``t = τ u`` with Gaussian
  timing jitter, fitted by least squares to the points whose *measured* times fall in a
  window ending at the event (as the estimator's window and causality do), against the
  same points selected by their *true* times.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import default_cache, log, markdown_table, recording_for, scenario_config  # noqa: E402
from time_surface_runs import run_time_surface  # noqa: E402

SECTIONS = ("steps", "time", "truncation")
SCENES = ("slider", "all_axes", "room_slider", "paper_slider")
NEARER = ("slider", "all_axes", "room_slider")

#: The issue's plain prototype: a plane over the whole neighbourhood, Benosman-style outlier
#: rejection, no rms check, a fixed refractory period of 60 ms (the paper network's).
PLAIN = {"model": "plane", "ahead_px": 100.0, "refractory": 0.06, "refractory_depth": 0.0, "hold_px": 0.0,
         "turn": 0.0, "outlier_px": 0.5, "max_rms_px": 100.0, "min_points": 6, "window_depth": 10.0}
#: One change at a time from PLAIN towards the defaults, each keeping the ones before it.
STEPS = [
    ("plain plane fit (radius 3, window 10 m / abs(A t) x 3 px, refractory 60 ms, no rms check)", {}),
    ("+ only pixels the edge has crossed (ahead_px -0.5): no stale points ahead of it", {"ahead_px": -0.5}),
    ("+ burst hold from the fit (hold_px 3, refractory_depth 10 m): no late burst events",
     {"refractory": 0.0, "refractory_depth": 10.0, "hold_px": 3.0}),
    ("+ nothing from before a turn (turn 0.2)", {"turn": 0.2}),
    ("+ fit checks (max_rms_px 0.25, outlier_px 0.25, min_points 8, window_depth 5 m)",
     {"max_rms_px": 0.25, "outlier_px": 0.25, "min_points": 8, "window_depth": 5.0}),
    ("+ trim the window's ends on fitted times (trim_px 0.5): no truncation", {"trim_px": 0.5}),
    ("defaults: lines along the motion (model rows, no trim)", None),
]


def nearer(name: str, duration: float, cache) -> object:
    config = scenario_config(name, duration)
    return recording_for(config.replace(name=f"{name}-gt-nearer-at-jumps", occlusion_depth="nearer_surface"), 0,
                         cache, quiet=True)


def section_steps(args) -> None:
    rows = []
    config = dict(PLAIN)
    for label, changes in STEPS:
        if changes is None:
            config = {}
        else:
            config.update(changes)
        row = [label]
        for name in SCENES:
            m = run_time_surface(recording_for(scenario_config(name, args.duration), 0, args.cache, quiet=True),
                                 **config)
            row.append(f"{m['median_rel_pct']:.1f} / {m['bias_pct']:+.1f} / {m['coverage_pct']:.1f}")
        for name in NEARER:
            m = run_time_surface(nearer(name, args.duration, args.cache), **config)
            row.append(f"{m['median_rel_pct']:.1f} / {m['bias_pct']:+.1f}")
        log(f"  {label[:60]}: {row[1:]}")
        rows.append(row)
    print("From the plain plane fit to the defaults, one change at a time (cells: median rel % / bias % / "
          "coverage %; 'nearer': ground truth of the occluding surface at contours):\n")
    print(markdown_table(["change"] + list(SCENES) + [f"{n} (nearer)" for n in NEARER], rows) + "\n")


def section_time(args) -> None:
    edges = [0.0, 0.1, 0.2, 0.3, 0.4, 0.6, 1.0]
    rows = []
    for name in SCENES:
        rec = recording_for(scenario_config(name, args.duration), 0, args.cache, quiet=True)
        m = run_time_surface(rec)
        e = m["evaluation"]
        valid = e.matches.valid
        t = (m["quality"]["t_event"][valid] - rec.events["t"][0]) * 1e-6
        rel = (m["depth"]["z"][valid] - e.matches.gt[valid]) / e.matches.gt[valid]
        row = [name]
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = (t >= lo) & (t < hi)
            row.append(f"{100 * np.median(rel[sel]):+.1f} ({100 * sel.mean():.0f} %)" if sel.sum() > 20 else "-")
        rows.append(row)
    print("Bias of the defaults by time since the motion started, % (share of the estimates):\n")
    print(markdown_table(["scenario"] + [f"{lo:g}-{hi:g} s" for lo, hi in zip(edges[:-1], edges[1:])], rows) + "\n")


def truncated_slope(jitter_px: float, window_px: float, radius: int = 3, trials: int = 4000, seed: int = 0,
                    by_true_time: bool = False) -> float:
    """Mean LS slope / true slope for a plane ``t = u`` (1 px per unit time) over a square of
    ``radius``, jitter ``jitter_px`` (Gaussian, in pixels of travel), keeping the points whose
    age relative to the centre event lies in ``[0, window_px]``."""
    rng = np.random.default_rng(seed)
    du, dv = np.meshgrid(np.arange(-radius, radius + 1), np.arange(-radius, radius + 1))
    u, v = du.ravel().astype(float), dv.ravel().astype(float)
    centre = (u == 0) & (v == 0)
    ratios = []
    for _ in range(trials):
        t = u + rng.normal(0.0, jitter_px, u.shape)  # edge moving to -u: pixels at +u fired earlier... t = u
        t = -t  # older (more negative) towards +u: the edge came from there
        t[centre] = 0.0
        age = -t if not by_true_time else u
        keep = (age >= 0) & (age <= window_px)
        if keep.sum() < 4:
            continue
        a = np.linalg.lstsq(np.c_[u[keep], v[keep], np.ones(keep.sum())], t[keep], rcond=None)[0]
        ratios.append(-a[0])
    return float(np.mean(ratios))


def section_truncation(args) -> None:
    rows = []
    for jitter in (0.0, 0.1, 0.2, 0.3):
        row = [f"{jitter:g}"]
        for window in (1.5, 2.5, 3.5, 6.0):
            by_measured = truncated_slope(jitter, window)
            by_true = truncated_slope(jitter, window, by_true_time=True)
            row.append(f"{100 * (by_measured - 1):+.1f} / {100 * (by_true - 1):+.1f}")
        rows.append(row)
    print("Truncation on a synthetic plane (radius 3): mean error of the fitted slope, %, points selected by "
          "their measured / their true age in [0, window] (the event itself at age 0):\n")
    print(markdown_table(["jitter px (sd)"] + [f"window {w:g} px" for w in (1.5, 2.5, 3.5, 6.0)], rows) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=",".join(SECTIONS))
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--cache", default=str(default_cache()))
    args = parser.parse_args(argv)
    args.cache = Path(args.cache) if args.cache else None
    for name in [s for s in args.only.split(",") if s]:
        if name not in SECTIONS:
            parser.error(f"unknown section {name!r}; known: {', '.join(SECTIONS)}")
        log(f"section {name}")
        globals()[f"section_{name}"](args)
    print("reproduce: python benchmarks/time_surface_bias.py" + (f" --only {args.only}" if args.only !=
                                                                   ",".join(SECTIONS) else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
