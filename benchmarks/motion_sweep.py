"""Both estimators on random scenes under general motion, by depth band and motion phase (by hand, not in CI).

    python benchmarks/motion_sweep.py                              # variants 100-103 (held out), 1 s each
    python benchmarks/motion_sweep.py --variants 0-5 --duration 0.5   # the tuning variants
    python benchmarks/motion_sweep.py --set window_px=8,min_points=5  # time-surface parameters changed

For every motion class of ``tofnet.sim.motion`` (``random_steady``, ``random_reversing``,
``random_forward``, ``random_shake``) and every variant, the scene is simulated (cached as
``accuracy.py`` caches, seed = variant), run through the paper's network and the
time-surface estimator (a shaking camera: both with eq. 7, ω from the 1 kHz poses, as
``tofnet run`` does), and scored with ``tofnet.eval.breakdown``. Variants 0-99 are for
tuning, 100 on for testing (docs/time_surface.md). Per class the runs are pooled: coverage
is estimates over events (overall, per true-depth band, per motion phase), errors are
medians over the pooled estimates. Text and markdown tables go to stdout, progress to stderr.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import (as_written, default_backend, default_cache, fmt, log, print_tables,  # noqa: E402
                      recording_for, reproduce, run_improved, run_network)

from tofnet.eval.breakdown import DEPTH_BANDS, PHASES, band_label, motion_phase  # noqa: E402
from tofnet.sim.motion import MOTIONS  # noqa: E402
from tofnet.sim.scenarios import scenario  # noqa: E402

BANDS = [band_label(lo, hi) for lo, hi in zip(DEPTH_BANDS[:-1], DEPTH_BANDS[1:])]


def parse_variants(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def parse_settings(text: str) -> dict:
    settings = {}
    for item in filter(None, text.split(",")):
        key, _, value = item.partition("=")
        try:
            settings[key.strip()] = int(value) if value.strip().lstrip("-").isdigit() else float(value)
        except ValueError:
            settings[key.strip()] = value.strip()
    return settings


class Pool:
    """Counts and relative errors of one (class, estimator), pooled over variants."""

    def __init__(self) -> None:
        self.events = defaultdict(int)
        self.estimates = defaultdict(int)
        self.rel: dict[str, list[np.ndarray]] = defaultdict(list)

    def add(self, run, phase_of_event: np.ndarray) -> None:
        e, rec = run.evaluation, run.recording
        gt_events = rec.gt_depth
        usable = np.isfinite(gt_events) & (gt_events > 0)
        event_band = np.searchsorted(DEPTH_BANDS, np.where(usable, gt_events, 0.0), side="right") - 1
        valid = e.matches.valid
        z, gt = run.result.depth["z"][valid].astype(np.float64), e.matches.gt[valid]
        rel = (z - gt) / gt
        band = np.searchsorted(DEPTH_BANDS, gt, side="right") - 1
        phase = phase_of_event[e.matches.event_index[valid]]
        self.events["all"] += e.events_in
        self.estimates["all"] += e.estimates
        self.rel["all"].append(rel)
        for i, label in enumerate(BANDS):
            self.events[label] += int(np.count_nonzero(usable & (event_band == i)))
            self.estimates[label] += int(np.count_nonzero(band == i))
            self.rel[label].append(rel[band == i])
        for i, label in enumerate(PHASES):
            self.events[label] += int(np.count_nonzero(phase_of_event == i))
            self.estimates[label] += int(np.count_nonzero(phase == i))
            self.rel[label].append(rel[phase == i])

    def coverage(self, group: str) -> float:
        return 100.0 * self.estimates[group] / self.events[group] if self.events[group] else math.nan

    def median(self, group: str) -> float:
        rel = np.concatenate(self.rel[group]) if self.rel[group] else np.zeros(0)
        return 100.0 * float(np.median(np.abs(rel))) if rel.size else math.nan

    def bias(self, group: str) -> float:
        rel = np.concatenate(self.rel[group]) if self.rel[group] else np.zeros(0)
        return 100.0 * float(np.median(rel)) if rel.size else math.nan


def scene_options(doc: str, motions: str, variants: str, settings: str) -> argparse.ArgumentParser:
    """The options of a script over the random scenes (``--motions``, ``--variants``, ``--duration``, ``--set``,
    ``--backend``, ``--cache``), with the script's own defaults."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--motions", default=motions, help=f"comma-separated (default {motions})")
    parser.add_argument("--variants", default=variants, help=f"e.g. 0-5 or 100,101 (default {variants})")
    parser.add_argument("--duration", type=float, default=1.0, help="seconds per variant (default 1)")
    parser.add_argument("--set", default=settings, help="time-surface parameters, e.g. window_px=8,min_points=5 "
                                                        f"(default {settings or 'none'})")
    parser.add_argument("--backend", default=None)
    parser.add_argument("--cache", default=str(default_cache()), help="simulation cache folder ('' = none)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = scene_options(__doc__, ",".join(MOTIONS), "100-103", "").parse_args(argv)
    motions = [m for m in args.motions.split(",") if m]
    variants = parse_variants(args.variants)
    settings = parse_settings(args.set)
    backend = args.backend or default_backend()
    cache = Path(args.cache) if args.cache else None
    pools: dict[tuple[str, str], Pool] = defaultdict(Pool)
    for motion in motions:
        for variant in variants:
            config = scenario(f"random_{motion}:{variant}", args.duration)
            rec = recording_for(config, variant, cache)
            rotation = None
            if motion == "shake":
                rec, rotation = as_written(rec, config, variant), "groundtruth"
            phase = motion_phase(config.trajectory, rec.events["t"] * 1e-6)
            start = time.perf_counter()
            paper = run_network(rec, backend=backend, rotation=rotation)
            improved = run_improved(rec, backend=backend, rotation=rotation, **settings)
            pools[(motion, "paper")].add(paper, phase)
            pools[(motion, "time surface")].add(improved, phase)
            log(f"{config.name}: {len(rec.events):,} events, coverage paper {100 * paper.evaluation.coverage:.1f} %, "
                f"time surface {100 * improved.evaluation.coverage:.1f} % ({time.perf_counter() - start:.1f} s)")

    header = ["motion", "estimator", "coverage %", "median %", "bias %"] + \
             [f"cov {b} %" for b in BANDS] + [f"med {b} %" for b in BANDS] + [f"cov {p} %" for p in PHASES] + \
             [f"med {p} %" for p in PHASES]
    rows = []
    for (motion, estimator), pool in pools.items():
        rows.append([motion, estimator, fmt(pool.coverage("all")), fmt(pool.median("all")), fmt(pool.bias("all"))]
                    + [fmt(pool.coverage(b)) for b in BANDS] + [fmt(pool.median(b)) for b in BANDS]
                    + [fmt(pool.coverage(p)) for p in PHASES] + [fmt(pool.median(p)) for p in PHASES])
    print_tables(header, rows, f"Random scenes, variants {args.variants}, {args.duration:g} s each, backend {backend}, "
                 f"time surface {settings or 'defaults'}; pooled per motion class")
    print(reproduce(f"motion_sweep.py --variants {args.variants}", [("--duration", args.duration, 1.0, "g"),
                    ("--motions", args.motions, ",".join(MOTIONS)), ("--set", args.set, "")]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
