"""Why wobble_slider's eq. 7 depth stays worse than the slider's (issue 12; run by hand, not in CI).

    python benchmarks/wobble_study.py      # slider and wobble_slider, esim pixels, 1 s, 240x180, seed 0

About 30 s on the shared 2 cores when it simulates both scenes, 6-9 s with them cached.

Both scenarios are simulated (cached like ``benchmarks/accuracy.py``) and run through
the paper's network (float backend, per-pixel ``A t``, 1 ms steps, default refractory)
with ``record_tot=True``. Each active depth neuron's two timestamps per measured axis are
traced back to the accepted input events (the trigger at the pixel, the facilitation
at the neighbour ``|count|`` steps earlier). Eq. 7 is then evaluated with the true
velocity and angular velocity at the trigger event's exact time, which makes its
relative error exactly ``e / r`` with ``e = f·td − 1`` (``f`` the true image motion at
the pixel from the true depth, ``td`` the measured time-of-travel vector) and
``r = 1 − (B ω)·td``. The tables split ``|rel|`` and ``e`` by: the timing used (1 ms
counts, or the two events' µs timestamps), the age of the facilitation and whether it
lies on the same surface (hypothesis: stale pairing with an earlier pass), the turn of
the true flow over the travel interval, and which axes were measured and how much of
the true image motion lies along the other axis (a missing or stale axis).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).parent))
from accuracy import (default_cache, fmt, log, parse_size, recording_for, reproduce, scenario_config,  # noqa: E402
                      text_table)

from tofnet.api import run  # noqa: E402
from tofnet.eval.match import match_estimates  # noqa: E402
from tofnet.eval.rotation import _motion, as_depth_array, depth_inputs, recompute_depth  # noqa: E402
from tofnet.networks import depth_network  # noqa: E402
from tofnet.sim.scenarios import ESIM_EXAMPLE_PIXELS  # noqa: E402

MIN_DEPTH, MAX_DEPTH = 0.05, 20.0  # the depth process's defaults, m
REFRACTORY_US = 60_000  # the input process's default


@njit(cache=True)
def accepted_mask(t, x, y, width, npix, t0, dt, refractory):  # pragma: no cover - numba
    """The input process's accept rule (refractory on any polarity, one event per pixel and step)."""
    last_t = np.full(npix, -(1 << 62), dtype=np.int64)
    last_step = np.full(npix, -1, dtype=np.int64)
    keep = np.zeros(t.shape[0], dtype=np.bool_)
    for i in range(t.shape[0]):
        if t[i] < t0:
            continue
        p = y[i] * width + x[i]
        step = (t[i] - t0) // dt
        if t[i] - last_t[p] < refractory or step == last_step[p]:
            continue
        keep[i] = True
        last_t[p] = t[i]
        last_step[p] = step
    return keep


def study(name: str, args) -> dict:
    config = scenario_config(name, args.duration, parse_size(args.size))
    if args.pixels == "esim":
        config = config.replace(**ESIM_EXAMPLE_PIXELS)
    recording = recording_for(config, args.seed, Path(args.cache) if args.cache else None)
    width, height = recording.sensor_size
    start = time.perf_counter()
    result, _ = run(recording, depth_network(recording.sensor_size, velocity={"per": "pixel"}), backend="float",
                    record_tot=True)
    log(f"  {name}: network ran in {time.perf_counter() - start:.1f} s, {len(result.depth):,} estimates")
    t0, dt_us = result.t0_us, result.timestep_us
    dt = dt_us * 1e-6
    inputs = depth_inputs(result.tot, width)
    everything = as_depth_array(inputs, np.zeros(len(inputs)), np.ones(len(inputs), bool), t0, dt_us)
    matches = match_estimates(everything, recording.events, recording.gt_depth, latency_steps=result.latency_steps,
                              t0_us=t0, timestep_us=dt_us)
    ev = recording.events
    ev_t = ev["t"].astype(np.int64)
    ev_x, ev_y = ev["x"].astype(np.int64), ev["y"].astype(np.int64)
    keep = accepted_mask(ev_t, ev_x, ev_y, width, width * height, t0, dt_us, REFRACTORY_US)
    acc = np.flatnonzero(keep)
    acc_key = (ev_y[acc] * width + ev_x[acc]) * (1 << 24) + (ev_t[acc] - t0) // dt_us
    order = np.argsort(acc_key)
    acc, acc_key = acc[order], acc_key[order]

    def accepted_event(px, py, step):
        """Index of the accepted event at pixel (px, py) in input step ``step``, or -1."""
        key = (py * width + px) * (1 << 24) + step
        pos = np.clip(np.searchsorted(acc_key, key), 0, len(acc_key) - 1)
        return np.where(acc_key[pos] == key, acc[pos], -1)

    trig = matches.event_index
    gt = matches.gt
    ok = inputs.measured & (trig >= 0) & np.isfinite(gt) & (gt > 0)
    trigger_step = inputs.step - 2
    t_trig = np.where(trig >= 0, ev_t[np.maximum(trig, 0)], 0)
    # Facilitating event per axis: the unit toward +u is facilitated by the pixel at u - 1.
    fac = {}
    for axis, signed in (("u", inputs.signed_x), ("v", inputs.signed_y)):
        dx = -np.sign(signed) if axis == "u" else np.zeros_like(signed)
        dy = -np.sign(signed) if axis == "v" else np.zeros_like(signed)
        idx = accepted_event(inputs.x + dx, inputs.y + dy, trigger_step - np.abs(signed))
        idx = np.where(signed != 0, idx, -1)
        fac[axis] = idx
    has_u, has_v = inputs.signed_x != 0, inputs.signed_y != 0
    found = (~has_u | (fac["u"] >= 0)) & (~has_v | (fac["v"] >= 0))
    log(f"  facilitating events found for {np.count_nonzero(found & ok):,} of {np.count_nonzero(ok):,} estimates")
    ok &= found
    sel = np.flatnonzero(ok)
    x, y, g = inputs.x[sel], inputs.y[sel], gt[sel]
    sx, sy = inputs.signed_x[sel].astype(float), inputs.signed_y[sel].astype(float)
    tt = t_trig[sel] * 1e-6
    motion = config.trajectory
    angular = motion if hasattr(motion, "angular_velocity_at") else None
    at, bw = _motion(tt, x, y, recording.intrinsics, motion, angular)
    flow = at / g[:, None] + bw
    td_count = np.column_stack([sx, sy]) * dt
    fu, fv = fac["u"][sel], fac["v"][sel]
    age_u = np.where(fu >= 0, (ev_t[np.maximum(trig[sel], 0)] - ev_t[np.maximum(fu, 0)]) * 1e-6, 0.0)
    age_v = np.where(fv >= 0, (ev_t[np.maximum(trig[sel], 0)] - ev_t[np.maximum(fv, 0)]) * 1e-6, 0.0)
    td_exact = np.column_stack([np.sign(sx) * age_u, np.sign(sy) * age_v])
    gt_all = recording.gt_depth
    fac_gt_ratio = np.ones(len(sel))
    for f, has in ((fu, has_u[sel]), (fv, has_v[sel])):
        ratio = np.where(has, gt_all[np.maximum(f, 0)] / g, 1.0)
        fac_gt_ratio = np.where(np.abs(np.log(ratio)) > np.abs(np.log(fac_gt_ratio)), ratio, fac_gt_ratio)
    # The true flow at the facilitation times: its turn over the travel interval.
    turn = np.zeros(len(sel))
    for f, has in ((fu, has_u[sel]), (fv, has_v[sel])):
        tf = np.where(has, ev_t[np.maximum(f, 0)] * 1e-6, tt)
        a0, b0 = _motion(tf, x, y, recording.intrinsics, motion, angular)
        f0 = a0 / g[:, None] + b0
        ang = np.abs(np.angle((flow[:, 0] + 1j * flow[:, 1]) / (f0[:, 0] + 1j * f0[:, 1]), deg=True))
        turn = np.maximum(turn, np.where(has, ang, 0.0))
    # The trigger pixel's previous accepted event before the trigger (time since, s).
    prev = accepted_previous(acc, ev_t, ev_x, ev_y, width, trig[sel])
    gap = np.where(prev >= 0, tt - ev_t[np.maximum(prev, 0)] * 1e-6, np.inf)

    out = {"name": name, "t": tt, "motion": motion, "angular": angular, "intrinsics": recording.intrinsics,
           "x": x, "y": y, "gt": g, "flow": flow, "at": at, "bw": bw, "td_count": td_count, "td_exact": td_exact,
           "has_u": has_u[sel], "has_v": has_v[sel], "age": np.maximum(age_u, age_v),
           "fac_gt_ratio": fac_gt_ratio, "turn": turn, "gap": gap,
           "t_fac": (np.where(fu >= 0, ev_t[np.maximum(fu, 0)] * 1e-6, tt),
                     np.where(fv >= 0, ev_t[np.maximum(fv, 0)] * 1e-6, tt))}
    # Cross-check: eq. 7 at the trigger step's centre as the rotation study computes it.
    z_study, _ = recompute_depth(inputs, intrinsics=recording.intrinsics, velocity=motion, angular=angular,
                                 t0_us=t0, timestep_us=dt_us, when="trigger")
    out["z_study"] = z_study[sel]
    return out


def accepted_previous(acc, ev_t, ev_x, ev_y, width, trig):
    """Per trigger event index, the accepted event at the same pixel just before it (-1 if none)."""
    pix = ev_y[acc] * width + ev_x[acc]
    order = np.lexsort((ev_t[acc], pix))
    a_sorted, p_sorted = acc[order], pix[order]
    key = p_sorted * (1 << 40) + ev_t[a_sorted]
    q = (ev_y[trig] * width + ev_x[trig]) * (1 << 40) + ev_t[trig]
    pos = np.searchsorted(key, q) - 1
    valid = (pos >= 0) & (p_sorted[np.maximum(pos, 0)] == ev_y[trig] * width + ev_x[trig])
    return np.where(valid, a_sorted[np.maximum(pos, 0)], -1)


def flow_at(o: dict, times: np.ndarray) -> np.ndarray:
    """True image motion (px/s) at each estimate's pixel and true depth at ``times`` (s)."""
    a, b = _motion(times, o["x"], o["y"], o["intrinsics"], o["motion"], o["angular"])
    return a / o["gt"][:, None] + b


def interval_flow(o: dict, samples: int = 9) -> np.ndarray:
    """Each axis's true flow averaged from its facilitating event to the trigger (px/s)."""
    out = np.zeros_like(o["flow"])
    for axis, t_fac in enumerate(o["t_fac"]):
        total = np.zeros(len(t_fac))
        for j in range(samples):
            total += flow_at(o, t_fac + (o["t"] - t_fac) * j / (samples - 1))[:, axis]
        out[:, axis] = total / samples
    return out


def eq7(o: dict, td: np.ndarray, flow: np.ndarray | None = None):
    """Eq. 7 with the true ``A t``, ``B ω`` at the trigger: depth (m), share ``r``, ``e = f·td − 1``, kept mask."""
    r = 1.0 - np.sum(o["bw"] * td, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.sum(o["at"] * td, axis=1) / r
    e = np.sum((o["flow"] if flow is None else flow) * td, axis=1) - 1.0
    return z, r, e, (r > 0) & (z > MIN_DEPTH) & (z < MAX_DEPTH)


def row(name: str, label: str, o: dict, z, e, sel, total) -> list[str]:
    if not sel.any():
        return [name, label, "0", "-", "-", "-", "-"]
    rel = (z[sel] - o["gt"][sel]) / o["gt"][sel]
    return [name, label, fmt(int(sel.sum())), fmt(100 * sel.sum() / total), fmt(100 * float(np.median(np.abs(rel)))),
            f"{100 * float(np.median(rel)):+.1f}", fmt(100 * float(np.median(np.abs(e[sel]))))]


def tables(o: dict) -> dict[str, list[list[str]]]:
    name = o["name"]
    z_c, _, e_c, keep_c = eq7(o, o["td_count"])
    z_x, _, e_x, keep = eq7(o, o["td_exact"])
    f_int = interval_flow(o)
    _, _, e_i, _ = eq7(o, o["td_exact"], f_int)
    n = int(keep.sum())
    same = np.abs(np.log(o["fac_gt_ratio"])) < 0.05
    short = o["age"] < 0.02
    t = {k: [] for k in ("timing", "pairing", "axes", "offset", "rule")}
    z_s = o["z_study"]
    t["timing"].append(row(name, "1 ms counts, motion at the trigger step's centre (rotation_study)", o, z_s, e_c,
                           (z_s > MIN_DEPTH) & (z_s < MAX_DEPTH) & np.isfinite(e_c), len(z_s)))
    t["timing"].append(row(name, "1 ms counts, motion at the trigger event", o, z_c, e_c, keep_c, len(z_c)))
    t["timing"].append(row(name, "µs event times (same pairs)", o, z_x, e_x, keep, len(z_x)))
    t["timing"].append(row(name, "µs event times, e from the interval's flow", o, z_x, e_i, keep, len(z_x)))
    for label, m in (("all", keep), ("other surface (facilitation's true depth differs > 5 %)", keep & ~same),
                     ("same surface, facilitation >= 20 ms old", keep & same & ~short),
                     ("same surface, facilitation < 20 ms old", keep & same & short)):
        t["pairing"].append(row(name, label, o, z_x, e_x, m, n) + [fmt(100 * float(np.median(np.abs(e_i[m]))))
                                                                    if m.any() else "-"])
    for lo, hi in ((0, 1), (1, 5), (5, 10), (10, 30), (30, 180)):
        m = keep & same & (o["turn"] >= lo) & (o["turn"] < hi)
        t["pairing"].append(row(name, f"same surface, true flow turns {lo}-{hi} deg in the interval", o, z_x, e_x, m, n)
                            + [fmt(100 * float(np.median(np.abs(e_i[m])))) if m.any() else "-"])
    for lo, hi in ((0, 0.08), (0.08, 0.15), (0.15, 0.3), (0.3, np.inf)):
        m = keep & (o["gap"] >= lo) & (o["gap"] < hi)
        t["pairing"].append(row(name, f"trigger pixel's previous event {lo * 1e3:g}-{hi * 1e3:g} ms before", o, z_x,
                                e_x, m, n) + [fmt(100 * float(np.median(np.abs(e_i[m])))) if m.any() else "-"])
    f = o["flow"]
    terms = np.abs(f * o["td_exact"])
    minor = np.where(np.abs(f[:, 0]) >= np.abs(f[:, 1]), terms[:, 1], terms[:, 0])
    both = o["has_u"] & o["has_v"]
    off_axis = np.abs(f[:, 1]) / np.hypot(f[:, 0], f[:, 1])
    for lo, hi in ((0, 0.03), (0.03, 0.1), (0.1, 0.3), (0.3, 1), (1, np.inf)):
        m = keep & same & both & (minor >= lo) & (minor < hi)
        t["axes"].append(row(name, f"both axes: |f td| of the minor axis {lo:g}-{hi:g}", o, z_x, e_x, m, n))
    for lo, hi in ((0, 0.05), (0.05, 0.1), (0.1, 0.2), (0.2, 0.4), (0.4, 1.01)):
        m = keep & same & o["has_u"] & ~o["has_v"] & (off_axis >= lo) & (off_axis < hi)
        t["axes"].append(row(name, f"u only: |f_v| / |f| {lo:g}-{hi:g}", o, z_x, e_x, m, n))
    m = keep & same & short
    t["offset"].append([name] + [fmt(100 * float(np.median(np.abs(np.sum(flow_at(o, o["t"] + d) * o["td_exact"], 1)
                                                                     - 1)[m])), 2) for d in OFFSETS])
    count_age = np.max(np.abs(o["td_count"]), axis=1)
    for limit in (None, 0.08, 0.04, 0.02):
        m = keep_c if limit is None else keep_c & (count_age <= limit + 1e-9)
        t["rule"].append(row(name, "all counts" if limit is None else f"reject counts > {limit * 1e3:g} steps", o,
                             z_c, e_c, m, int(keep_c.sum())))
    # What a neuron could compute itself: the minor axis's share of f·td = 1 with its own depth.
    with np.errstate(divide="ignore", invalid="ignore"):
        f_own = o["at"] / z_c[:, None] + o["bw"]
    own = np.abs(f_own * o["td_count"])
    own_minor = np.where(np.abs(f_own[:, 0]) >= np.abs(f_own[:, 1]), own[:, 1], own[:, 0])
    for limit in (0.3, 0.1):
        m = keep_c & (own_minor <= limit)
        t["rule"].append(row(name, f"reject own minor-axis |f td| > {limit:g}", o, z_c, e_c, m, int(keep_c.sum())))
    return t


#: Offsets (s) of the time the true flow is sampled at, from the trigger event.
OFFSETS = (-0.02, -0.01, -0.005, 0.0, 0.005, 0.01)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="slider,wobble_slider")
    parser.add_argument("--duration", type=float, default=1.0, help="seconds per scenario (default 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", default="240x180")
    parser.add_argument("--pixels", choices=("default", "esim"), default="esim",
                        help="esim (default here): ESIM's example pixels; default: C 0.2 with 0.03 mismatch")
    parser.add_argument("--cache", default=str(default_cache()), help="simulation cache folder ('' = none)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    all_tables: dict[str, list[list[str]]] = {}
    for name in [s for s in args.scenarios.split(",") if s]:
        log(f"{name}:")
        for key, rows in tables(study(name, args)).items():
            all_tables.setdefault(key, []).extend(rows)
    print(f"Wobble study: {args.duration:g} s, seed {args.seed}, {args.size}, {args.pixels} pixels, 1 ms steps, "
          f"per-pixel A t, true motion and depth; eq. 7's relative error is e / r with e = f.td - 1")
    base = ["scenario", "estimates", "share %", "median |rel| %", "median rel %", "median |e| %"]
    print("\n1. Timing: the network's 1 ms counts against the µs timestamps of the same two events per axis")
    print(text_table(base[:1] + ["td from"] + base[1:], all_tables["timing"]))
    print("\n2. Pairing and flow turn (µs timing; last column: e with each axis's flow averaged over its interval)")
    print(text_table(base[:1] + ["estimates with"] + base[1:] + ["|e| interval %"], all_tables["pairing"]))
    print("\n3. The axis the image barely moves along (µs timing, same-surface pairs)")
    print(text_table(base[:1] + ["estimates with"] + base[1:], all_tables["axes"]))
    print("\n4. Ground-truth timing: median |e| % with the true flow sampled this long after the trigger event")
    print("   (same-surface pairs < 20 ms old, µs timing; a consistent truth is best near the interval's middle)")
    print(text_table(["scenario"] + [f"{d * 1e3:+g} ms" for d in OFFSETS], all_tables["offset"]))
    print("\n5. Rules (network's 1 ms counts): reject an axis count above a limit, or a minor-axis term |f td| above a"
          " limit\n   with f = A t / z + B w from the neuron's own depth z (share %: of all the scenario's estimates)")
    print(text_table(base[:1] + ["rule"] + base[1:], all_tables["rule"]))
    cmd = reproduce("wobble_study.py", [("--scenarios", args.scenarios, "slider,wobble_slider"),
                                        ("--duration", args.duration, 1.0), ("--seed", args.seed, 0),
                                        ("--size", args.size, "240x180"), ("--pixels", args.pixels, "esim")])
    print(f"\n{cmd}   ({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
