"""Why the time surface rejects near first events on the random scenes: each sampled fit replayed against the truth.

    python benchmarks/motion_causes.py                        # steady and reversing, tuning variants 0-2, no noise
    python benchmarks/motion_causes.py --samples 200 --sim contrast_sigma=0

For each scene (``random_<motion>:<variant>``, ``--duration`` s, background activity ``--noise``
Hz/px, 0 by default) the estimator is fed the recording with ``record_rejected``; up to
``--samples`` first events per reason (``nothing_behind``, ``too_few_points``, ``ill_conditioned``,
``bad_fit``, ``emitted``) whose true depth is below ``--near`` m are drawn, the estimator is fed
again up to each of them, and its step for that event replayed from the state (the kernel's own
``behind_steps``, ``since_reversal``, ``gather``, ``to_travel`` and ``fit_rows``; the samples whose replayed verdict differs from the
kernel's are counted on stderr). Each point the fit saw is found in the event stream (its pixel,
polarity and time) and compared with the truth: its true depth (another surface: the square
straddles an occluding contour) and its distance from the line of the true slope through the
median of its line (``+``: more than 1 px newer, a later edge already passed the pixel; ``-``:
older, the pixel did not fire for this edge). Printed (markdown, docs/time_surface.md section 7d):
why the pixels behind gave no support; per reason the share of points of each kind and each
sample's most frequent wrong kind; and how many ``bad_fit`` fits an oracle that drops the wrong
points (by kind) would have saved, at what median error, and why the others still fail.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import default_cache, fmt, log, markdown_table, recording_for  # noqa: E402
from motion_sweep import parse_settings, parse_variants  # noqa: E402
from time_surface_runs import config_for, trajectory_rows  # noqa: E402

from tofnet.kernels import time_surface as ts  # noqa: E402
from tofnet.kernels.time_surface_estimator import TimeSurfaceEstimator, cos_turn  # noqa: E402
from tofnet.kernels.time_surface_fit import (FIT_ILL_CONDITIONED, FIT_OK, FIT_OVER_RMS, FIT_TOO_FEW, N_L,  # noqa: E402
                                           fit_rows)
from tofnet.kernels.time_surface_gather import behind_steps, expand, gather  # noqa: E402
from tofnet.kernels.time_surface_travel import (RING, S_CHANGE, S_FIRST, advance, pace, since_reversal,  # noqa: E402
                                                to_travel, travel_at)
from tofnet.kernels.velocity import velocity_term  # noqa: E402
from tofnet.sim.scenarios import scenario  # noqa: E402

REASONS = (ts.NOTHING_BEHIND, ts.TOO_FEW_POINTS, ts.ILL_CONDITIONED, ts.BAD_FIT, ts.EMITTED)
KINDS = ("on the line", "other surface", "newer edge", "older edge")
#: A point further than this (px) from the true line of its line is another edge's.
OFF_PX = 1.0
#: A point whose true depth differs by more than this (relative) is another surface's.
OTHER_SURFACE = 0.1


def replay(est: TimeSurfaceEstimator, ev: np.ndarray, i: int, rows) -> dict:
    """The kernel's step for event ``i`` (a fitted first event) from ``est``'s state before it (pinhole, no rotation)."""
    c, (fx, fy, cx, cy), r = est.config, est.config.intrinsics, int(est.config.radius)
    width = int(c.sensor_size[0])
    row, dt, t0 = width + 2 * r, c.timestep_us, est.t0_us
    t, x, y, p = int(ev["t"][i]), int(ev["x"][i]), int(ev["y"][i]), int(ev["p"][i])
    k = (t - t0) // dt
    update = (k + c.latency_steps - 1) // c.update_every
    table, first = rows(update, 1)
    v = table[update - first]
    ring, state = est._ring.copy(), est._ring_state.copy()
    advance(ring, state, k, v, dt * 1e-6)
    surface = est._surface.copy()
    flat = surface.reshape(-1)
    at_cell = p * surface.shape[1] + (y + r) * row + x + r
    flat[at_cell] = t  # the event starts an edge: the surface takes it before the fit
    ax, ay = velocity_term(v[0], v[1], v[2], float(x), float(y), fx, fy, cx, cy)
    speed2 = ax * ax + ay * ay
    speed = math.sqrt(speed2)
    fu, fv = ax / speed, ay / speed
    g = (-fx * fu, -fy * fv, (x - cx) * fu + (y - cy) * fv)
    here = travel_at(ring, t, t0, dt, 1.0 / dt, *g, 0.0, 0.0, 0.0)[0]
    behind = []
    for du, dv in zip(behind_steps(ax, speed2), behind_steps(ay, speed2)):
        when = int(flat[at_cell - dv * row - du])
        old = t - when > (RING - 2) * dt
        travel = math.inf if old else here - travel_at(ring, when, t0, dt, 1.0 / dt, *g, 0.0, 0.0, 0.0)[0]
        behind.append((x - du, y - dv, when, travel, du * fu + dv * fv))
    out = dict(t=t, x=x, y=y, p=p, speed=speed, behind=behind,
               supported=all(0.0 <= b[3] <= c.behind_depth * b[4] for b in behind))
    if not out["supported"]:
        return out
    reach = c.window_depth * r
    suggested = max(pace(b[3], b[4]) for b in behind)
    reach = min(reach, c.window_px * suggested) if c.window_px > 0 else reach
    # all of the window since the last change of the velocity: the kernel fits in time (section 7a)
    linear_from = t0 + state[S_CHANGE] * dt if state[S_CHANGE] != state[S_FIRST] else ts.NEVER
    linear = reach < speed * 1e-6 * (t - linear_from)
    across = (fx * fv, -fy * fu, (y - cy) * fu - (x - cx) * fv)  # Aᵀf⊥ (pinhole): the image motion across f
    window = int(math.floor(reach / (speed * 1e-6))) if linear else since_reversal(
        ring, k, t, t0, dt, int(state[S_FIRST]), *g, 0.0, 0.0, 0.0, reach, *across, cos_turn(c.max_turn))
    size = 2 * (2 * r + 1) ** 2 + 1
    ps_, pw, pt, pg = np.zeros(size), np.zeros(size), np.zeros(size), np.zeros(size, np.int64)
    middle = 2 * r + 1
    n = gather(flat, at_cell, row, r, t, window, fu, fv, c.ahead_px, middle, ps_, pw, pt, pg)
    if linear:
        expand(ps_, pt, n, v[2] / speed)  # each point's own image speed, as the kernel's time path
    z_guess = suggested if suggested < math.inf else c.window_depth
    raw = [(ps_[m], pw[m]) for m in range(n)]  # where each point's pixel is (to_travel moves them)
    points, kept = [], 0
    for m, (s_raw, w_raw) in enumerate(raw):  # one at a time: which ones ``to_travel`` keeps, and where
        one = [np.array([v]) for v in (ps_[m], pw[m], pt[m])] + [np.array([pg[m]])]
        if not linear and not to_travel(ring, *one, 1, t, t0, dt, *g, 0.0, 0.0, 0.0, z_guess, reach, *across,
                                        0.0, 0.0, 0.0, middle):
            continue
        du, dv = s_raw * fu - w_raw * fv, s_raw * fv + w_raw * fu
        pu, pv = x + int(round(du)), y + int(round(dv))
        ps_[kept], pw[kept], pt[kept], pg[kept] = one[0][0], one[1][0], one[2][0], one[3][0]
        points.append((ps_[kept], pt[kept], int(pg[kept]), pu, pv,
                       int(flat[p * surface.shape[1] + (pv + r) * row + pu + r]), pw[kept]))
        kept += 1
    n = kept
    out["points"] = points
    out["fit"] = fit_rows(ps_.copy(), pw.copy(), pt.copy(), pg.copy(), n, c.min_points, c.min_spread, c.outlier_px, c.iterations,
                          np.zeros((4 * r + 3, N_L)), np.zeros(4 * r + 3, np.int64))
    return out


def verdict(sample: dict, c) -> int:
    if not sample["supported"]:
        return ts.NOTHING_BEHIND
    code, _, _, _, _, rms = sample["fit"]
    return {FIT_TOO_FEW: ts.TOO_FEW_POINTS, FIT_ILL_CONDITIONED: ts.ILL_CONDITIONED}.get(
        code, ts.BAD_FIT if code != FIT_OK or rms > c.max_rms_px else ts.EMITTED)


def behind_cause(sample: dict, z: float, depth_of, c) -> str:
    """Why the pixels behind did not support the event: the first of the two that failed."""
    for bx, by, when, travel, distance in sample["behind"]:
        if when <= ts.NEVER // 2:
            return "never fired (this polarity)"
        if not abs(depth_of(bx, by, sample["p"], when) - z) <= OTHER_SURFACE * z:
            return "another surface"
        if travel < 0.0:
            return "fired before the last reversal"
        if travel > c.behind_depth * distance:
            return "fired an older edge"
    return "?"


def point_kinds(sample: dict, z: float, depth_of) -> list[int]:
    """Per point: the index in ``KINDS`` against the truth (true slope ``z`` through each line's median)."""
    lines = defaultdict(list)
    for m, q in enumerate(sample["points"]):
        lines[q[2]].append(m)
    kinds = [0] * len(sample["points"])
    for members in lines.values():
        offset = float(np.median([sample["points"][m][1] - z * sample["points"][m][0] for m in members]))
        for m in members:
            s, travel, _, pu, pv, when, _ = sample["points"][m]
            off = (travel - z * s - offset) / z if len(members) > 1 else 0.0
            other = not abs(depth_of(pu, pv, sample["p"], when) - z) <= OTHER_SURFACE * z
            kinds[m] = 1 if other else 2 if off > OFF_PX else 3 if off < -OFF_PX else 0
    return kinds


def oracle(sample: dict, kinds: list[int], drop: tuple[int, ...], c) -> tuple[float, int]:
    """The slope of the fit of the points whose kind is not in ``drop`` (NaN: it still fails) and its code."""
    kept = [q for q, kind in zip(sample["points"], kinds) if kind not in drop]
    n = len(kept)
    ps_, pw, pt, pg = np.zeros(n + 1), np.zeros(n + 1), np.zeros(n + 1), np.zeros(n + 1, np.int64)
    for m, q in enumerate(kept):
        ps_[m], pw[m], pt[m], pg[m] = q[0], q[6], q[1], q[2]
    r = int(c.radius)
    code, tau, _, _, _, rms = fit_rows(ps_, pw, pt, pg, n, c.min_points, c.min_spread, c.outlier_px, c.iterations,
                                       np.zeros((4 * r + 3, N_L)), np.zeros(4 * r + 3, np.int64))
    if code == FIT_OK and rms > c.max_rms_px:
        code = FIT_OVER_RMS
    return (tau if code == FIT_OK else math.nan), code


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--motions", default="steady,reversing", help="comma-separated (no shake: no rotation here)")
    parser.add_argument("--variants", default="0-2", help="tuning variants (default 0-2)")
    parser.add_argument("--duration", type=float, default=0.5, help="seconds per variant (default 0.5)")
    parser.add_argument("--samples", type=int, default=120, help="first events per reason and variant (default 120)")
    parser.add_argument("--near", type=float, default=2.0, help="only events truly nearer than this, m (default 2)")
    parser.add_argument("--noise", type=float, default=0.0, help="background activity, Hz/px (default 0)")
    parser.add_argument("--sim", default="", help="other SimConfig fields, e.g. contrast_sigma=0")
    parser.add_argument("--cache", default=str(default_cache()), help="simulation cache folder ('' = none)")
    args = parser.parse_args(argv)
    cache = Path(args.cache) if args.cache else None
    sim = parse_settings(args.sim)
    behind_rows, kind_rows, oracle_rows = [], [], []
    drops = {"other surface": (1,), "newer edge": (2,), "older edge": (3,), "all three": (1, 2, 3)}
    for motion in filter(None, args.motions.split(",")):
        behind, shares, worst, rescued, errors, totals = Counter(), defaultdict(Counter), defaultdict(Counter), \
            Counter(), defaultdict(list), Counter()
        failed = defaultdict(Counter)
        disagree = 0
        for variant in parse_variants(args.variants):
            config = dataclasses.replace(scenario(f"random_{motion}:{variant}", args.duration),
                                         noise_rate=args.noise, **sim)
            rec = recording_for(config, variant, cache, quiet=True)
            ev, truth = rec.events, rec.gt_depth
            c = config_for(rec)
            t0 = int(ev["t"][0])
            rows = trajectory_rows(rec, t0, c, False)
            _, quality = TimeSurfaceEstimator(c, t0).feed(ev, rows, record_rejected=True)
            width, height = rec.sensor_size
            key = ((ev["t"].astype(np.int64) * width + ev["x"]) * height + ev["y"]) * 2 + ev["p"]
            order = np.argsort(key, kind="stable")

            def depth_of(x, y, p, t, key=key[order], order=order, width=width, height=height, truth=truth):
                at = np.searchsorted(key, ((t * width + x) * height + y) * 2 + p)
                return float(truth[order[at]]) if at < len(key) and key[at] == ((t * width + x) * height + y) * 2 + p \
                    else math.nan

            rng = np.random.default_rng(variant)
            near = truth[quality["index"]] < args.near
            picks = []
            for reason in REASONS:
                pool = np.flatnonzero((quality["reason"] == reason) & near)
                picks += list(rng.choice(pool, min(args.samples, len(pool)), replace=False)) if len(pool) else []
            est, fed = TimeSurfaceEstimator(c, t0), 0
            for q in sorted(picks, key=lambda q: quality["index"][q]):
                i, reason = int(quality["index"][q]), int(quality["reason"][q])
                est.feed(ev[fed:i], rows)
                fed = i
                sample = replay(est, ev, i, rows)
                if verdict(sample, c) != reason:  # the kernel's own verdict stands (a tie in the outliers, say)
                    disagree += 1
                z = float(truth[i])
                totals[reason] += 1
                if reason == ts.NOTHING_BEHIND:
                    behind[behind_cause(sample, z, depth_of, c)] += 1
                    continue
                kinds = point_kinds(sample, z, depth_of)
                shares[reason].update(kinds)
                bad = Counter(k for k in kinds if k)
                worst[reason][max(bad, key=bad.get) if bad else 0] += 1
                if reason == ts.BAD_FIT:
                    for label, drop in drops.items():
                        slope, code = oracle(sample, kinds, drop, c)
                        failed[label][code] += 1
                        if slope == slope:
                            rescued[label] += 1
                            errors[label].append(abs(slope - z) / z)
            log(f"{config.name}: {len(picks)} samples")
        log(f"{motion}: the replay's verdict differs from the kernel's on {disagree} of {sum(totals.values())} samples")
        n = totals[ts.NOTHING_BEHIND]
        behind_rows += [[motion, cause, fmt(100.0 * count / n)] for cause, count in behind.most_common()]
        for reason in REASONS[1:]:
            points, samples = sum(shares[reason].values()), totals[reason]
            kind_rows.append([motion, ts.COUNT_NAMES[reason], f"{samples}"]
                             + [fmt(100.0 * shares[reason][k] / points) for k in range(len(KINDS))]
                             + [fmt(100.0 * worst[reason][k] / samples) for k in range(len(KINDS))])
        n = totals[ts.BAD_FIT]
        oracle_rows += [[motion, label, fmt(100.0 * rescued[label] / n),
                         fmt(100.0 * float(np.median(errors[label])) if errors[label] else math.nan)]
                        + [fmt(100.0 * failed[label][code] / n) for code in (FIT_OVER_RMS, FIT_TOO_FEW,
                                                                              FIT_ILL_CONDITIONED)]
                        for label in drops]
    print(f"Random scenes, variants {args.variants}, {args.duration:g} s, noise {args.noise:g} Hz/px"
          f"{', ' + args.sim if args.sim else ''}; first events truly nearer than {args.near:g} m, up to "
          f"{args.samples} per reason and variant\n")
    print("Why the pixels behind gave no support (% of the sampled nothing_behind):\n")
    print(markdown_table(["motion", "first failing pixel behind", "%"], behind_rows))
    print("\nThe points the fits saw: % of the points of each kind, then % of the samples whose most frequent "
          "wrong kind it is (first column: no point off the true line by more than 1 px):\n")
    print(markdown_table(["motion", "reason", "samples"] + [f"points {k} %" for k in KINDS]
                         + ["samples: none off %"] + [f"samples: {k} %" for k in KINDS[1:]], kind_rows))
    print("\nbad_fit fits an oracle would save by dropping the wrong points of one kind (% of the sampled bad_fit, "
          "and the median relative error of the saved fits):\n")
    print(markdown_table(["motion", "dropped", "saved %", "median %", "still over max_rms_px %", "too few %",
                          "ill conditioned %"], oracle_rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
