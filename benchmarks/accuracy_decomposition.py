"""Where the depth error comes from: controlled experiments, one factor at a time (run by hand, not in CI).

    python benchmarks/accuracy_decomposition.py                  # every section (about 5 min with the fixed backend)
    python benchmarks/accuracy_decomposition.py --only factors,noise

Sections (each prints a markdown table; docs/accuracy.md quotes them):

- ``attribution``: how the ground truth is labelled at occluding contours (the
  simulator's rule or the nearer surface); slider, all_axes and room_slider (1 s) at
  the default refractory period, errors
  binned by steps per pixel (how long the image takes to move one pixel, from the
  true depth and exact ``A t``), by true depth and (all_axes) by trajectory segment,
  next to the discretisation floor: the error the 1 ms step alone would give.
- ``factors``: slider and room_slider (0.5 s), each factor changed alone from the
  defaults, then together: refractory, threshold mismatch, per-event threshold
  noise instead of fixed-pattern, edge sharpness, contrast threshold, distance 2,
  a 0.1 ms step (room_slider with all of ESIM's example pixels is paper_slider).
- ``depth``: a textured fronto-parallel plane at 0.35-8 m (steps per pixel 3-73),
  with and without threshold mismatch, at the default refractory and at one longer
  than a burst.
- ``texture``: the plane at 2 m with texture features of 3-48 px.
- ``noise``: the plane at 2 m, threshold noise 0-0.05, fixed-pattern or per event,
  contrast threshold 0.2 or 0.5.
- ``velocity``: all_axes and forward with ``A t`` per patch (paper) or per pixel.

Per-event threshold noise is not a simulator option: this script swaps the
simulator's event kernel for one that draws a pixel's next threshold after each of
its events (``N(C, sigma)``, clipped to C +- 4 sigma), the temporal noise ESIM
models (ESIM redraws per pixel and render interval), and caches those recordings
under their own key.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import (attribution, binned, default_backend, default_cache, discretisation_floor,  # noqa: E402
                      fmt, log, markdown_table, recording_for, reproduce, run_network, scenario_config)
import tofnet.sim.engine as sim_engine  # noqa: E402
from tofnet.processes.input import DEFAULT_REFRACTORY  # noqa: E402
from tofnet.sim import Plane, Scene, SimConfig, Texture, constant  # noqa: E402
from tofnet.sim.camera import DEFAULT_INTRINSICS  # noqa: E402
from tofnet.sim.dvs import MIN_THRESHOLD  # noqa: E402

SECTIONS = ("attribution", "factors", "depth", "texture", "noise", "velocity")
FX = DEFAULT_INTRINSICS.fx


# --- per-event threshold noise (ESIM-like temporal noise) --------------------------------------------------------


@njit(cache=True)
def _seed(seed):  # pragma: no cover - numba
    np.random.seed(seed)


@njit(cache=True)
def _emit_per_event(l0, l1, d0, d1, ref, c_on, c_off, t0, t1, width, depth_jump, nearer_at_jumps, out_t, out_x,
                    out_y, out_p, out_d, n, mean_on, mean_off, sigma):  # pragma: no cover - numba
    """``tofnet.sim.dvs.emit_crossings`` with ``c_on``/``c_off`` as each pixel's *current* thresholds,
    redrawn from ``N(mean, sigma)`` (clipped to mean +- 4 sigma) after each event of that polarity."""
    span = t1 - t0
    for i in range(l0.shape[0]):
        a = l0[i]
        b = l1[i]
        if b == a:
            continue
        up = b > a
        za = d0[i]
        zb = d1[i]
        jump = abs(zb - za) > depth_jump * min(za, zb)
        r = ref[i]
        while True:
            c = c_on[i] if up else c_off[i]
            level = r + c if up else r - c
            if (up and level > b) or ((not up) and level < b):
                break
            frac = min(max((level - a) / (b - a), 0.0), 1.0)
            out_t[n] = np.int64(np.floor(t0 + frac * span + 0.5))
            out_x[n] = i % width
            out_y[n] = i // width
            out_p[n] = 1 if up else 0
            if jump:
                out_d[n] = min(za, zb) if nearer_at_jumps else (za if frac < 0.5 else zb)
            else:
                out_d[n] = za + frac * (zb - za)
            n += 1
            r = level
            mean = mean_on if up else mean_off
            draw = mean + sigma * min(max(np.random.normal(), -4.0), 4.0)
            draw = max(draw, 0.01)
            if up:
                c_on[i] = draw
            else:
                c_off[i] = draw
        ref[i] = r
    return n


@njit(cache=True)
def _count_bound(l0, l1, ref, low):  # pragma: no cover - numba
    """An upper bound of the events ``_emit_per_event`` writes: every threshold is at least ``low``."""
    total = 0
    for i in range(l0.shape[0]):
        if l1[i] > l0[i]:
            d = l1[i] - ref[i]
        elif l1[i] < l0[i]:
            d = ref[i] - l1[i]
        else:
            continue
        if d >= low:
            total += int(d / low) + 1
    return total


@contextlib.contextmanager
def per_event_noise(config: SimConfig, sigma: float, seed: int):
    """Inside: ``generate(config)`` (which must have ``contrast_sigma=0``) draws thresholds per event."""
    assert config.contrast_sigma == 0
    mean_on, mean_off = config.contrast_on, config.contrast_off
    low = max(min(mean_on, mean_off) - 4 * sigma, MIN_THRESHOLD)
    saved = sim_engine.emit_crossings, sim_engine.count_crossings
    _seed(seed)

    def emit(l0, l1, d0, d1, ref, c_on, c_off, *rest):
        return _emit_per_event(l0, l1, d0, d1, ref, c_on, c_off, *rest, mean_on, mean_off, sigma)

    def count(l0, l1, ref, c_on, c_off):
        return _count_bound(l0, l1, ref, low)

    sim_engine.emit_crossings, sim_engine.count_crossings = emit, count
    try:
        yield
    finally:
        sim_engine.emit_crossings, sim_engine.count_crossings = saved


def recording(config: SimConfig, cache: Path | None, seed: int = 0, per_event_sigma: float = 0.0):
    """``recording_for``, with per-event threshold noise when ``per_event_sigma > 0``."""
    if per_event_sigma <= 0:
        return recording_for(config, seed, cache)
    tagged = config.replace(name=f"{config.name}-per-event-sigma-{per_event_sigma:g}")
    with per_event_noise(tagged, per_event_sigma, seed):
        return recording_for(tagged, seed, cache)


# --- scenes ----------------------------------------------------------------------------------------------------


def sharper(config: SimConfig, blur: float) -> SimConfig:
    """``config`` with every texture smoothed by ``blur`` texels instead of its own."""
    scene = config.scene
    objects = tuple(dataclasses.replace(o, texture=dataclasses.replace(o.texture, blur=blur)) for o in scene.objects)
    scene = dataclasses.replace(scene, objects=objects,
                                background=dataclasses.replace(scene.background, blur=blur))
    return config.replace(scene=scene, name=f"{config.name}-blur-{blur:g}")


def plane(z: float, *, feature_px: float = 12.0, sigma: float = 0.03, contrast: float = 0.2, blur: float = 0.7,
          speed: float = 0.55, duration: float = 0.5, kind: str = "shapes") -> SimConfig:
    """A fronto-parallel textured plane filling the view at ``z`` m, camera sliding along +x at ``speed``.

    Texture features are ``feature_px`` pixels across at that depth, whatever the depth.
    """
    width = 1.4 * z + speed * duration + 0.4
    height = 1.1 * z + 0.4
    texture = Texture(kind, scale=feature_px * z / FX, blur=blur)
    scene = Scene(objects=(Plane(center=(0.0, 0.0, z), size=(width, height), texture=texture, name="plane"),),
                  background_depth=z + 1.0, background=Texture("uniform"))
    return SimConfig(f"plane-z{z:g}-f{feature_px:g}-s{sigma:g}-c{contrast:g}-b{blur:g}", scene,
                     constant((speed, 0.0, 0.0), duration), duration, contrast_on=contrast, contrast_off=contrast,
                     contrast_sigma=sigma)


def _seconds(text: str) -> float:
    from tofnet.units import seconds
    return seconds(text)


def evaluate_against(r, other):
    """The evaluation of run ``r`` against the ground truth of ``other`` (a recording with the same events)."""
    from tofnet.eval.metrics import evaluate
    meta = {"t0_us": r.result.t0_us, "timestep_us": r.result.timestep_us, "latency_steps": r.result.latency_steps}
    return evaluate(other, r.result.depth, meta, window_s=0)


# --- sections --------------------------------------------------------------------------------------------------


def _row(label: str, r, extra: list[str] | None = None) -> list[str]:
    m = r.metrics()
    return [label] + (extra or []) + [fmt(m["median_rel_pct"]), fmt(m["mean_rel_pct"]), f"{m['bias_pct']:+.1f}",
                                      fmt(m["coverage_pct"]), fmt(m["median_abs_m"], 3)]


METRIC_COLS = ["median rel %", "mean rel %", "bias %", "coverage %", "median abs m"]


def section_attribution(args) -> None:
    rows = []
    for name in ("slider", "all_axes", "room_slider", "room_all_axes"):
        config = scenario_config(name, args.long)
        rec = recording_for(config, args.seed, args.cache)
        nearer_config = config.replace(name=f"{name}-gt-nearer-at-jumps", occlusion_depth="nearer_surface")
        nearer = recording_for(nearer_config, args.seed, args.cache)
        assert np.array_equal(rec.events, nearer.events)
        relabelled = 100 * np.count_nonzero(rec.gt_depth != nearer.gt_depth) / len(rec.events)
        r = run_network(rec, backend=args.backend, refractory=args.refractory)
        e = evaluate_against(r, nearer)
        m = r.metrics()
        rows.append([name, fmt(relabelled), fmt(m["median_rel_pct"]), f"{m['bias_pct']:+.1f}", fmt(m["mean_rel_pct"]),
                     fmt(e.errors.median_rel_pct), f"{e.errors.bias_rel_pct:+.1f}", fmt(e.errors.mean_rel_pct)])
        log(f"  occlusion labels: {rows[-1]}")
    print(f"### ground truth at occluding contours, {args.long:g} s, refractory {args.refractory}\n")
    print("An event where the depth jumps between two renders (an occluding contour crossed the pixel) is labelled\n"
          "by the simulator with the depth of the render nearer in time; the edge that moved is the occluding\n"
          "(nearer) surface's, whose depth the network measures. Same events, both labels:\n")
    print(markdown_table(["scenario", "events relabelled %", "median rel % (sim)", "bias % (sim)", "mean rel % (sim)",
                          "median rel % (nearer)", "bias % (nearer)", "mean rel % (nearer)"], rows) + "\n")
    rows = []
    base = scenario_config("slider", args.long)
    for label, objects in (("desk scene", base.scene.objects), ("background only (objects removed)", ())):
        config = base.replace(scene=dataclasses.replace(base.scene, objects=objects),
                              name="slider" if objects else "slider-background-only")
        r = run_network(recording_for(config, args.seed, args.cache), backend=args.backend, refractory=args.refractory)
        a = attribution(r)
        on_background = a["gt"] >= base.scene.background_depth - 0.01
        steps = np.round(a["z"] / (a["gt"] / a["n"]))  # counted steps: z / (metres per step of this pixel)
        short = 100 * np.count_nonzero(steps[on_background] <= 10) / max(1, np.count_nonzero(on_background))
        rel = a["rel"][on_background]
        rows.append([label, fmt(int(on_background.sum())), fmt(100 * np.median(np.abs(rel))),
                     f"{100 * np.median(rel):+.1f}", fmt(float(np.median(a["n"][on_background]))), fmt(short)])
    print(f"slider's estimates labelled with the background (true depth {base.scene.background_depth:g} m):\n")
    print(markdown_table(["scene", "estimates", "median rel %", "bias %", "steps/px (true)",
                          "counted <= 10 steps %"], rows) + "\n")
    for name in ("slider", "all_axes", "room_slider"):
        rec = recording_for(scenario_config(name, args.long), args.seed, args.cache)
        r = run_network(rec, backend=args.backend, refractory=args.refractory)
        a = attribution(r)
        floor = discretisation_floor(a["n"])
        m = r.metrics()
        print(f"### {name}, {args.long:g} s, refractory {args.refractory}: median {m['median_rel_pct']:.1f} %, "
              f"bias {m['bias_pct']:+.1f} %, discretisation floor {100 * np.median(floor):.1f} %\n")
        edges = [0, 2, 4, 6, 8, 12, 16, 24, 32, 64, 256, math.inf]
        rows = [[f"{b['lo']:g}-{b['hi']:g}", fmt(b["share_pct"]), fmt(b["median_rel_pct"]), f"{b['bias_pct']:+.1f}",
                 fmt(b["floor_pct"])] for b in binned(a["n"], a["rel"], edges, floor) if b["share_pct"] > 0]
        print(markdown_table(["steps/px", "share %", "median rel %", "bias %", "floor %"], rows) + "\n")
        edges = [0, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.01, 4, 5, 6, 8, 10.01]
        rows = [[f"{b['lo']:g}-{b['hi']:g}", fmt(b["share_pct"]), fmt(b["median_rel_pct"]), f"{b['bias_pct']:+.1f}",
                 fmt(b["floor_pct"])] for b in binned(a["gt"], a["rel"], edges, floor) if b["share_pct"] > 0]
        print(markdown_table(["true depth m", "share %", "median rel %", "bias %", "floor %"], rows) + "\n")
        if name == "all_axes":
            segs = rec.trajectory.segments
            bounds = rec.trajectory.boundaries
            window = _seconds(args.refractory)
            since = a["t"] + r.result.t0_us * 1e-6 - bounds[np.minimum(a["seg"], len(segs) - 1)]
            rows = []
            for i, s in enumerate(segs):
                sel = a["seg"] == i
                if not sel.any():
                    continue
                early, late = sel & (since < window), sel & (since >= window)
                rows.append([str(i), "(" + ", ".join(f"{v:g}" for v in s.velocity) + ")", fmt(int(sel.sum())),
                             fmt(100 * np.median(np.abs(a["rel"][sel]))), f"{100 * np.median(a['rel'][sel]):+.1f}",
                             fmt(100 * np.median(floor[sel])), fmt(float(np.median(a["n"][sel]))),
                             fmt(100 * np.median(np.abs(a["rel"][early]))), fmt(100 * np.median(np.abs(a["rel"][late])))])
            print(markdown_table(["segment", "velocity m/s", "estimates", "median rel %", "bias %", "floor %",
                                  "steps/px", f"median rel % first {args.refractory}", "median rel % after"],
                                 rows) + "\n")


def section_factors(args) -> None:
    d = args.refractory
    ms01 = {"timestep": "0.1ms", "counter_bits": 12}
    for name in ("slider", "room_slider"):
        base = scenario_config(name, args.short)
        ideal = base.replace(contrast_sigma=0.0)
        runs: list[tuple[str, SimConfig, float, dict]] = [
            (f"defaults (refractory {d}, C 0.2, sigma 0.03 fixed, blur 0.7 texel, distance 1, 1 ms)", base, 0.0, {}),
            ("refractory 5 ms", base, 0.0, {"refractory": "5ms"}),
            ("refractory 20 ms", base, 0.0, {"refractory": "20ms"}),
            ("refractory 100 ms", base, 0.0, {"refractory": "100ms"}),
            ("threshold mismatch sigma 0 (ideal pixels)", ideal, 0.0, {}),
            ("threshold noise per event (sigma 0.03) instead of fixed", ideal, 0.03, {}),
            ("sharper edges (blur 0.3 texel)", sharper(base, 0.3), 0.0, {}),
            ("contrast threshold 0.5", base.replace(contrast_on=0.5, contrast_off=0.5), 0.0, {}),
            ("distance 2", base, 0.0, {"distance": 2}),
            ("0.1 ms step, 12-bit counters (no discretisation)", base, 0.0, ms01),
            ("sigma 0 + sharper edges", sharper(ideal, 0.3), 0.0, {}),
            ("sigma 0 + sharper edges + C 0.5 (ESIM's example pixels)",
             sharper(ideal.replace(contrast_on=0.5, contrast_off=0.5), 0.3), 0.0, {}),
            ("sigma 0 + sharper edges + 0.1 ms step", sharper(ideal, 0.3), 0.0, ms01),
        ]
        rows = []
        for label, config, per_event, net in runs:
            rec = recording(config, args.cache, args.seed, per_event)
            net = {"refractory": d, **net}
            r = run_network(rec, backend=args.backend, **net)
            a = attribution(r)
            floor = discretisation_floor(a["n"], net.get("distance", 1))  # n is in this run's steps
            rows.append(_row(label, r) + [fmt(100 * float(np.median(floor))), fmt(float(np.median(a["n"])))])
            log(f"  factors {name}: {label}: {rows[-1][1:]}")
        print(f"### {name}, {args.short:g} s, one factor at a time\n")
        print(markdown_table(["change from the defaults"] + METRIC_COLS + ["floor %", "steps/px"], rows) + "\n")


def section_depth(args) -> None:
    rows = []
    for z in (0.35, 0.5, 1.0, 2.0, 4.0, 8.0):
        n = z / (FX * 0.55) / 1e-3
        long_refr = f"{int(math.ceil(3 * n / 5) * 5)}ms"  # about three pixel crossings: longer than any burst
        for sigma in (0.0, 0.03):
            rec = recording(plane(z, sigma=sigma), args.cache, args.seed)
            for refr in (args.refractory, long_refr):
                r = run_network(rec, backend=args.backend, refractory=refr)
                a = attribution(r)
                floor = 100 * float(np.median(discretisation_floor(a["n"])))
                rows.append(_row(f"{z:g}", r, [fmt(n), fmt(sigma, 2), refr]) + [fmt(floor)])
                log(f"  depth: {rows[-1]}")
    print(f"### plane at depth Z, shapes of 12 px, slider 0.55 m/s, {0.5:g} s\n")
    print(markdown_table(["Z m", "steps/px", "sigma", "refractory"] + METRIC_COLS + ["floor %"], rows) + "\n")


def section_texture(args) -> None:
    rows = []
    for feature in (3, 6, 12, 24, 48):
        for kind in ("shapes", "checker"):
            rec = recording(plane(2.0, feature_px=feature, kind=kind), args.cache, args.seed)
            for refr in dict.fromkeys((args.refractory, "20ms")):
                r = run_network(rec, backend=args.backend, refractory=refr)
                rows.append(_row(f"{feature}", r, [kind, refr]))
                log(f"  texture: {rows[-1]}")
    print("### plane at 2 m (18 steps/px), sigma 0.03, texture feature size in pixels\n")
    print(markdown_table(["feature px", "texture", "refractory"] + METRIC_COLS, rows) + "\n")


def section_noise(args) -> None:
    rows = []
    cases = [(s, "fixed", 0.2) for s in (0.0, 0.01, 0.02, 0.03, 0.05)]
    cases += [(s, "per event", 0.2) for s in (0.01, 0.02, 0.03, 0.05)]
    cases += [(0.0, "fixed", 0.5), (0.03, "fixed", 0.5), (0.03, "per event", 0.5)]
    for sigma, kind, contrast in cases:
        for blur in (0.7, 0.3):
            if kind == "fixed":
                rec = recording(plane(2.0, sigma=sigma, contrast=contrast, blur=blur), args.cache, args.seed)
            else:
                rec = recording(plane(2.0, sigma=0.0, contrast=contrast, blur=blur), args.cache, args.seed, sigma)
            r = run_network(rec, backend=args.backend, refractory="50ms")
            rows.append(_row(fmt(sigma, 2), r, [kind, fmt(contrast, 1), fmt(blur, 1)]))
            log(f"  noise: {rows[-1]}")
    print("### plane at 2 m (18 steps/px), shapes of 12 px, refractory 50 ms (longer than a burst)\n")
    print(markdown_table(["sigma", "noise", "C", "blur texel"] + METRIC_COLS, rows) + "\n")


def section_velocity(args) -> None:
    rows = []
    for name in ("all_axes", "forward"):
        rec = recording_for(scenario_config(name, args.long), args.seed, args.cache)
        for per in ("patch", "pixel"):
            r = run_network(rec, backend=args.backend, refractory=args.refractory, velocity_per=per)
            a = attribution(r)
            seg_med = []
            for i in range(len(rec.trajectory.segments)):
                sel = a["seg"] == i
                seg_med.append(fmt(100 * np.median(np.abs(a["rel"][sel]))) if sel.any() else "-")
            rows.append(_row(name, r, [per]) + [" / ".join(seg_med)])
            log(f"  velocity: {rows[-1]}")
    print(f"### A t per patch (paper) or per pixel, {args.long:g} s\n")
    print(markdown_table(["scenario", "A t"] + METRIC_COLS + ["median rel % per segment"], rows) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=",".join(SECTIONS), help=f"sections: {', '.join(SECTIONS)}")
    parser.add_argument("--refractory", default=DEFAULT_REFRACTORY)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--long", type=float, default=1.0, help="seconds of the built-in scenarios (default 1)")
    parser.add_argument("--short", type=float, default=0.5, help="seconds of the factor runs (default 0.5)")
    parser.add_argument("--backend", default=None)
    parser.add_argument("--cache", default=str(default_cache()))
    args = parser.parse_args(argv)
    args.backend = args.backend or default_backend()
    args.cache = Path(args.cache) if args.cache else None
    sections = [s for s in args.only.split(",") if s]
    for s in sections:
        if s not in SECTIONS:
            parser.error(f"unknown section {s!r}; expected {', '.join(SECTIONS)}")
    print(f"Accuracy decomposition: seed {args.seed}, 240x180, backend {args.backend}, default refractory "
          f"{args.refractory}\n")
    for s in sections:
        start = time.perf_counter()
        log(f"section {s}")
        print(f"## {s}\n")
        globals()[f"section_{s}"](args)
        sys.stdout.flush()
        log(f"section {s}: {time.perf_counter() - start:.0f} s")
    print(reproduce("accuracy_decomposition.py", [("--only", args.only, ",".join(SECTIONS)),
                                                  ("--refractory", args.refractory, DEFAULT_REFRACTORY)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
