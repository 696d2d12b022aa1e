"""Depth accuracy behind a distorted lens, with and without undistortion (run by hand, not in CI).

    python benchmarks/undistort_accuracy.py                       # slider, all_axes, forward; 1 s; both lenses
    python benchmarks/undistort_accuracy.py --scenarios slider --duration 0.5

Each scenario is simulated (``tofnet.sim``, cached as in ``accuracy.py``) through a pinhole
and through each lens: ``davis240c``, ECD ``slider_depth``'s DAVIS240C radtan coefficients
(k1 -0.368, k2 0.150, p1 -0.0003, p2 -0.0008, k3 0), and ``dsec_like``, an equidistant
(fisheye) lens with DSEC-like coefficients (-0.04, 0.01, -0.003, 0.0006). The simulator casts
each pixel's ray through the lens (``tofnet.sim.lens``), so events and their ground-truth
depth come from the distorted camera. Each distorted recording is run by the paper's network
(1 ms steps, 8-bit counters, default refractory, ``A t`` per 30 px patch, fixed backend):
- ``lens ignored``: as the paper, a pinhole assumed (``tofnet run --no-undistort``);
- ``A t through the lens``: the default; the velocity process evaluates each patch's
  ``A t`` at its undistorted centre and takes it onto the raw sensor with the lens's
  Jacobian (``tofnet.kernels.lens``); raw pixels, the fused kernel;
- ``undistort process``: an ``UndistortProcess`` between input and time of travel moves
  the spikes to undistorted pixels (and the velocity process sees a pinhole); its
  estimates are scored against the events moved likewise (``tofnet.eval.undistorted``).
Coverage is estimates over all events of the recording. Then the speed of the fixed
backend on the distorted ``slider``: fused paper chain, the paper chain unfused, and the
network with the undistort process (unfused), best of three. Text and markdown on stdout.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import default_cache, fmt, log, print_tables, recording_for, reproduce, scenario_config  # noqa: E402
from tofnet.api import run  # noqa: E402
from tofnet.eval.metrics import evaluate  # noqa: E402
from tofnet.eval.undistorted import undistorted_recording  # noqa: E402
from tofnet.io.recording import Intrinsics  # noqa: E402
from tofnet.networks import depth_network  # noqa: E402

LENSES = {"davis240c": ("radtan", (-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0)),
          "dsec_like": ("equidistant", (-0.04, 0.01, -0.003, 0.0006))}
SCENARIOS = "slider,all_axes,forward"


def score(recording, result, undistorted_lens=None) -> dict:
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
    seen = recording if undistorted_lens is None else undistorted_recording(recording, undistorted_lens,
                                                                            recording.sensor_size)
    e = evaluate(seen, result.depth, meta, window_s=0)
    counts = result.counts.get("undistort", {})
    return {"estimates": e.estimates, "coverage_pct": 100 * e.estimates / len(recording.events),
            "median_rel_pct": e.errors.median_rel_pct, "mean_rel_pct": e.errors.mean_rel_pct,
            "bias_pct": e.errors.bias_rel_pct, "left_image": counts.get("left_image"), "merged": counts.get("merged")}


def best_of(runs: int, action) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return min(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default=SCENARIOS)
    parser.add_argument("--lenses", default=",".join(LENSES))
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cache", default=str(default_cache()))
    args = parser.parse_args(argv)
    cache = Path(args.cache) if args.cache else None
    names = [s for s in args.scenarios.split(",") if s]
    lenses = [s for s in args.lenses.split(",") if s]
    rows = []
    for name in names:
        base = scenario_config(name, args.duration)
        rec = recording_for(base, args.seed, cache)
        result, _ = run(rec, depth_network(rec.sensor_size), backend="fixed")
        rows.append([name, "pinhole", "raw pixels", score(rec, result)])
        for lens_name in lenses:
            model, coefficients = LENSES[lens_name]
            k = base.intrinsics
            lens = Intrinsics(k.fx, k.fy, k.cx, k.cy, coefficients, model)
            rec = recording_for(base.replace(intrinsics=lens), args.seed, cache)
            ignored = depth_network(rec.sensor_size, velocity={"distortion_model": "none"})
            result, _ = run(rec, ignored, backend="fixed")
            rows.append([name, lens_name, "lens ignored (--no-undistort)", score(rec, result)])
            result, _ = run(rec, depth_network(rec.sensor_size), backend="fixed")
            rows.append([name, lens_name, "A t through the lens (default)", score(rec, result)])
            result, _ = run(rec, depth_network(rec.sensor_size, undistort={}), backend="fixed")
            rows.append([name, lens_name, "undistort process", score(rec, result, lens)])
            for row in rows[-3:]:
                m = row[3]
                log(f"  {name} {lens_name} {row[2]}: median {m['median_rel_pct']:.1f} %, bias {m['bias_pct']:+.1f} %")

    header = ["scenario", "lens", "network", "estimates", "coverage %", "median rel %", "mean rel %", "bias %",
              "left image", "merged"]
    table = [[n, lens, how, fmt(m["estimates"]), fmt(m["coverage_pct"]), fmt(m["median_rel_pct"]),
              fmt(m["mean_rel_pct"]), f"{m['bias_pct']:+.1f}", fmt(m["left_image"]), fmt(m["merged"])]
             for n, lens, how, m in rows]
    print_tables(header, table, f"Depth accuracy behind a distorted lens, {args.duration:g} s per scenario, seed "
                 f"{args.seed}, 240x180, 1 ms steps, 8-bit counters, default refractory, A t per 30 px patch")

    # Speed: what the undistort process costs on the fixed backend (it runs the graph model by model).
    from tofnet.backends.event_driven import FixedBackend
    model, coefficients = LENSES[lenses[0]]
    base = scenario_config("slider", args.duration)
    k = base.intrinsics
    rec = recording_for(base.replace(intrinsics=Intrinsics(k.fx, k.fy, k.cx, k.cy, coefficients, model)), args.seed,
                        cache)
    paper, lensed = depth_network(rec.sensor_size), depth_network(rec.sensor_size, undistort={})
    FixedBackend().run(lensed, rec)  # compile the models' kernels once
    FixedBackend(fuse=False).run(paper, rec)
    fused = best_of(3, lambda: FixedBackend().run(paper, rec))
    unfused = best_of(3, lambda: FixedBackend(fuse=False).run(paper, rec))
    with_undistort = best_of(3, lambda: FixedBackend().run(lensed, rec))
    n = len(rec.events)
    speed = [["paper chain, fused (raw pixels)", f"{fused:.3f}", f"{n / fused / 1e6:.2f}", "1.0"],
             ["paper chain, unfused", f"{unfused:.3f}", f"{n / unfused / 1e6:.2f}", f"{unfused / fused:.1f}"],
             ["with the undistort process (unfused)", f"{with_undistort:.3f}", f"{n / with_undistort / 1e6:.2f}",
              f"{with_undistort / fused:.1f}"]]
    speed_header = ["fixed backend, slider " + lenses[0], "wall s (best of 3)", "M events/s", "x fused"]
    print(f"Speed on slider through {lenses[0]}, {n:,} events, {args.duration:g} s:")
    print_tables(speed_header, speed)
    print(reproduce("undistort_accuracy.py", [("--scenarios", args.scenarios, SCENARIOS),
                                              ("--lenses", args.lenses, ",".join(LENSES)),
                                              ("--duration", args.duration, 1.0), ("--seed", args.seed, 0)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
