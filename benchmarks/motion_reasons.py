"""Where the time-surface estimator's first events go on the random scenes, by motion class and depth band.

    python benchmarks/motion_reasons.py                           # tuning variants 0-7, 1 s each
    python benchmarks/motion_reasons.py --noise 0                 # the same scenes without background activity
    python benchmarks/motion_reasons.py --noise 0 --sim contrast_sigma=0   # ... and without threshold mismatch
    python benchmarks/motion_reasons.py --set max_rms_px=0.3 --motions reversing

For every motion class of ``tofnet.sim.motion`` and every variant (cached as ``accuracy.py``
caches; a shaking camera with ω from the 1 kHz poses, as ``motion_sweep.py`` runs it) the
estimator is fed the whole recording with ``record_rejected``, so every first event comes back
with the count it ended in (``time_surface.COUNT_NAMES``). Per class, pooled over the variants
and per true-depth band of the event (``tofnet.eval.breakdown.DEPTH_BANDS``): the events, the
first events, the share of the first events per reason, and the coverage and median relative
error of the estimates (docs/time_surface.md, section 7d). ``--noise`` replaces the scenes'
background activity (events per pixel per second; 0: none), ``--sim`` other ``SimConfig`` fields
(``contrast_sigma=0``: equal thresholds). Only the time surface runs (the
paper network: ``motion_sweep.py``). Markdown to stdout, progress to stderr.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import as_written, default_cache, fmt, log, markdown_table, recording_for  # noqa: E402
from motion_sweep import parse_settings, parse_variants  # noqa: E402
from time_surface_runs import config_for, trajectory_rows  # noqa: E402

from tofnet.eval.breakdown import DEPTH_BANDS, band_label  # noqa: E402
from tofnet.eval.metrics import evaluate  # noqa: E402
from tofnet.kernels import time_surface as ts  # noqa: E402
from tofnet.kernels.time_surface_estimator import TimeSurfaceEstimator  # noqa: E402
from tofnet.sim.motion import MOTIONS  # noqa: E402
from tofnet.sim.scenarios import scenario  # noqa: E402

BANDS = [band_label(lo, hi) for lo, hi in zip(DEPTH_BANDS[:-1], DEPTH_BANDS[1:])]
ALL = len(BANDS)  # the row of every event (with or without a usable true depth)
#: The reasons shown (the rest are rare on these scenes and summed into "other").
SHOWN = ("nothing_behind", "too_few_points", "ill_conditioned", "bad_fit", "emitted")


def band_of(depth: np.ndarray) -> np.ndarray:
    """Index of each depth's band in ``DEPTH_BANDS`` (-1: no usable depth)."""
    usable = np.isfinite(depth) & (depth > 0)
    return np.where(usable, np.searchsorted(DEPTH_BANDS, np.where(usable, depth, 0.0), side="right") - 1, -1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--motions", default=",".join(MOTIONS), help="comma-separated (default: all)")
    parser.add_argument("--variants", default="0-7", help="e.g. 0-7 (default: tuning variants 0-7)")
    parser.add_argument("--duration", type=float, default=1.0, help="seconds per variant (default 1)")
    parser.add_argument("--set", default="", help="time-surface parameters, e.g. window_px=8,min_points=5")
    parser.add_argument("--noise", type=float, default=None, help="background activity, events/px/s (default: "
                        "each scene's own)")
    parser.add_argument("--sim", default="", help="SimConfig fields, e.g. contrast_sigma=0,max_step_px=0.1")
    parser.add_argument("--cache", default=str(default_cache()), help="simulation cache folder ('' = none)")
    args = parser.parse_args(argv)
    settings = parse_settings(args.set)
    sim = parse_settings(args.sim)
    cache = Path(args.cache) if args.cache else None
    rows = []
    for motion in filter(None, args.motions.split(",")):
        events = np.zeros(len(BANDS) + 1, np.int64)
        reasons = np.zeros((len(BANDS) + 1, ts.N_COUNTS), np.int64)
        rel: dict[int, list[np.ndarray]] = defaultdict(list)
        for variant in parse_variants(args.variants):
            config = scenario(f"random_{motion}:{variant}", args.duration)
            if args.noise is not None:
                config = dataclasses.replace(config, noise_rate=args.noise)
            config = dataclasses.replace(config, **sim)
            rec = recording_for(config, variant, cache, quiet=True)
            rotation = motion == "shake"
            if rotation:
                rec = as_written(rec, config, variant)
            ts_config = config_for(rec, **settings)
            t0 = int(rec.events["t"][0])
            estimator = TimeSurfaceEstimator(ts_config, t0)
            depth, quality = estimator.feed(rec.events, trajectory_rows(rec, t0, ts_config, rotation),
                                            record_rejected=True)
            band = band_of(rec.gt_depth)
            events[:ALL] += np.bincount(band[band >= 0], minlength=len(BANDS))[:len(BANDS)]
            events[ALL] += len(rec.events)
            first_band = band[quality["index"]]
            reasons[ALL] += np.bincount(quality["reason"], minlength=ts.N_COUNTS)[:ts.N_COUNTS]
            for b in range(len(BANDS)):
                reasons[b] += np.bincount(quality["reason"][first_band == b], minlength=ts.N_COUNTS)[:ts.N_COUNTS]
            emitted = quality["reason"] == ts.EMITTED
            meta = {"t0_us": t0, "timestep_us": ts_config.timestep_us, "latency_steps": ts_config.latency_steps}
            matches = evaluate(rec, depth[emitted], meta, window_s=0).matches
            valid = matches.valid
            gt = matches.gt[valid]
            errors = (depth["z"][emitted][valid] - gt) / gt
            estimate_band = band_of(gt)
            for b in range(len(BANDS)):
                rel[b].append(errors[estimate_band == b])
            rel[ALL].append(errors)
            log(f"{config.name}: {len(rec.events):,} events, {int(emitted.sum()):,} estimates")
        for b, label in enumerate(BANDS + ["all"]):
            first = int(reasons[b].sum())
            share = [100.0 * reasons[b][ts.COUNT_NAMES.index(name)] / first if first else float("nan")
                     for name in SHOWN]
            errors = np.concatenate(rel[b]) if rel[b] else np.zeros(0)
            coverage = 100.0 * errors.size / events[b] if events[b] else float("nan")
            median = 100.0 * float(np.median(np.abs(errors))) if errors.size else float("nan")
            rows.append([motion, label, f"{events[b]:,}", f"{first:,}"] + [fmt(v) for v in share]
                        + [fmt(coverage), fmt(median)])
    header = ["motion", "band", "events", "first events"] + [f"{name.replace('_', ' ')} %" for name in SHOWN] + \
        ["coverage %", "median %"]
    noise = "" if args.noise is None else f", noise {args.noise:g} Hz/px"
    noise += f", {args.sim}" if args.sim else ""
    print(f"Random scenes, variants {args.variants}, {args.duration:g} s each{noise}, time surface "
          f"{settings or 'defaults'}; first events per reason (% of the band's first events), pooled per class")
    print()
    print(markdown_table(header, rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
