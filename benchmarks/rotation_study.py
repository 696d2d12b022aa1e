"""Offline accuracy study of paper eq. 7 (rotation) before it is in the depth neurons (run by hand, not in CI).

    python benchmarks/rotation_study.py                      # slider and the rotation scenarios: 1 s, 240x180, seed 0
    python benchmarks/rotation_study.py --duration 0.3 --scenarios wobble_slider

Each scenario is simulated (cached like ``benchmarks/accuracy.py``) and run through the
paper's network unchanged (eq. 8, per-pixel ``A t``, 1 ms steps, 8-bit counters, default
refractory) with ``record_tot=True``. Every active depth neuron's depth is then
recomputed from its counters (``tofnet.eval.rotation``) with eq. 8 and eq. 7, the
velocity and angular velocity taken at the trigger or averaged over the travel
interval, the angular velocity from the 1 kHz poses (slerp derivative) or from the
simulated gyroscope (noise-free, or noisy and biased), and scored against the
per-event ground truth. The last table splits eq. 7's error by translational share
``r``: if a timing error ``e`` becomes ``e / r``, ``|rel| * r`` stays flat across
bins while ``|rel|`` grows as ``r`` falls; eq. 8's bias there is ``r - 1``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from accuracy import (default_cache, fmt, log, parse_size, recording_for, reproduce, scenario_config,  # noqa: E402
                      text_table)

from tofnet.api import run  # noqa: E402
from tofnet.eval.match import match_estimates  # noqa: E402
from tofnet.eval.rotation import as_depth_array, depth_inputs, recompute_depth, share_split  # noqa: E402
from tofnet.io.groundtruth import Trajectory  # noqa: E402
from tofnet.io.rotation import PoseAngularVelocity, gyroscope_from_imu  # noqa: E402
from tofnet.networks import depth_network  # noqa: E402
from tofnet.sim.rotation import ImuModel, imu_samples  # noqa: E402
from tofnet.sim.scenarios import ESIM_EXAMPLE_PIXELS  # noqa: E402

MIN_DEPTH, MAX_DEPTH = 0.05, 20.0  # the depth process's defaults, m


def pose_source(config) -> PoseAngularVelocity:
    """The angular velocity of the poses ``groundtruth.txt`` holds (``pose_rate`` per second, slerped)."""
    traj = config.trajectory
    times = np.arange(int(np.floor(config.duration * config.pose_rate + 1e-9)) + 1) / config.pose_rate
    return PoseAngularVelocity(Trajectory(times, traj.position_at(times), traj.quaternion_at(times)))


def true_translational_share(inputs, gt, recording, trajectory, timing) -> np.ndarray:
    """``r`` from the truth: ``(A t / Z)·td / ((A t / Z + B ω)·td)`` at the trigger, true depth, exact motion.

    Only the direction of the measured ``td`` enters, not its (noisy) length; NaN
    where the true flow does not move along the measured direction.
    """
    k = recording.intrinsics
    dt = timing["timestep_us"] * 1e-6
    t = timing["t0_us"] * 1e-6 + (inputs.step - 2 + 0.5) * dt
    v, w = trajectory.velocity_at(t), trajectory.angular_velocity_at(t)
    x, y = inputs.x - k.cx, inputs.y - k.cy
    at = np.column_stack([-k.fx * v[:, 0] + x * v[:, 2], -k.fy * v[:, 1] + y * v[:, 2]])
    bw = np.column_stack([(x * y / k.fy) * w[:, 0] - (k.fx + x * x / k.fx) * w[:, 1] + (k.fx / k.fy) * y * w[:, 2],
                          (k.fy + y * y / k.fy) * w[:, 0] - (x * y / k.fx) * w[:, 1] - (k.fy / k.fx) * x * w[:, 2]])
    td = np.column_stack([inputs.signed_x, inputs.signed_y]).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        translation = np.sum(at * td, axis=1) / gt
        total = translation + np.sum(bw * td, axis=1)
        return np.where(total > 0, translation / total, np.nan)


def study(name: str, args):
    config = scenario_config(name, args.duration, parse_size(args.size))
    if args.pixels == "esim":
        config = config.replace(**ESIM_EXAMPLE_PIXELS)
    recording = recording_for(config, args.seed, Path(args.cache) if args.cache else None)
    start = time.perf_counter()
    net = depth_network(recording.sensor_size, velocity={"per": "pixel"})
    result, _ = run(recording, net, backend="float", record_tot=True)
    log(f"  {name}: network ran in {time.perf_counter() - start:.1f} s, {len(result.depth):,} estimates")
    timing = {"t0_us": result.t0_us, "timestep_us": result.timestep_us}
    inputs = depth_inputs(result.tot, recording.sensor_size[0])
    everything = as_depth_array(inputs, np.zeros(len(inputs)), np.ones(len(inputs), bool), **timing)
    gt = match_estimates(everything, recording.events, recording.gt_depth, latency_steps=result.latency_steps,
                         **timing).gt
    valid = np.isfinite(gt) & (gt > 0)
    events_in = len(recording.events)
    rotating = hasattr(config.trajectory, "angular_velocity_at")
    poses = pose_source(config) if rotating else None
    gyro = gyroscope_from_imu(imu_samples(config.replace(imu=ImuModel()), args.seed)) if rotating else None
    noisy = gyroscope_from_imu(imu_samples(config.replace(imu=ImuModel(
        gyro_noise_density=args.gyro_noise, gyro_bias=(args.gyro_bias,) * 3)), args.seed)) if rotating else None

    def depth(angular, when):
        return recompute_depth(inputs, intrinsics=recording.intrinsics, velocity=recording.trajectory,
                               angular=angular, when=when, **timing)

    rows, results = [], {}

    def score(label, z, share, min_share=None):
        keep = inputs.measured & (z > MIN_DEPTH) & (z < MAX_DEPTH)
        if min_share is not None:
            keep &= share > min_share
        rel = (z[keep & valid] - gt[keep & valid]) / gt[keep & valid]
        rows.append([name, label, fmt(int(keep.sum())), fmt(100 * keep.sum() / events_in),
                     fmt(100 * float(np.median(np.abs(rel))) if rel.size else float("nan")),
                     f"{100 * float(np.median(rel)):+.1f}" if rel.size else "-",
                     "-" if min_share is None else fmt(int((inputs.measured & (share <= min_share)).sum()))])
        results[label] = (z, share, keep)

    # The network's own output first: the recomputation must reproduce it.
    network = as_depth_array(inputs, *depth(None, "network")[:1], inputs.measured, **timing)
    mine = np.sort(network[(network["z"] > MIN_DEPTH) & (network["z"] < MAX_DEPTH)], order=["step", "y", "x"])
    theirs = np.sort(result.depth, order=["step", "y", "x"])
    same = len(mine) == len(theirs) and np.allclose(mine["z"], theirs["z"], rtol=1e-9, atol=1e-12)
    log(f"  eq. 8 recomputed from the tot spikes {'equals' if same else 'DIFFERS FROM'} the network's output "
        f"({len(mine):,} vs {len(theirs):,} estimates)")
    score("eq. 8, network timing", *depth(None, "network"))
    score("eq. 8, trigger", *depth(None, "trigger"))
    score("eq. 8, interval", *depth(None, "interval"))
    if rotating:
        score("eq. 7, poses, trigger", *depth(poses, "trigger"), 0.0)
        score("eq. 7, poses, interval", *depth(poses, "interval"), 0.0)
        score("eq. 7, gyro, interval", *depth(gyro, "interval"), 0.0)
        score("eq. 7, noisy gyro, interval", *depth(noisy, "interval"), 0.0)
        for r_min in (0.1, 0.25, 0.5):
            score(f"eq. 7, poses, interval, r > {r_min}", *depth(poses, "interval"), r_min)

    split_rows, filter_rows = [], []
    if rotating:
        z7, share, keep7 = results["eq. 7, poses, interval"]
        z8 = results["eq. 8, interval"][0]
        sel = keep7 & valid
        rel7 = (z7[sel] - gt[sel]) / gt[sel]
        rel8 = (z8[sel] - gt[sel]) / gt[sel]
        true_share = true_translational_share(inputs, gt, recording, config.trajectory, timing)[sel]
        for label, by, out in (("true r", true_share, split_rows), ("estimated r", share[sel], filter_rows)):
            for a, b in zip(share_split(by, rel7), share_split(by, rel8)):
                if a["n"]:
                    out.append([name, f"{a['lo']:g} .. {a['hi']:g}", fmt(a["n"]), f"{a['share']:.2f}",
                                fmt(100 * a["median_rel"]), f"{100 * a['bias']:+.1f}", fmt(100 * a["rel_times_share"]),
                                f"{100 * b['bias']:+.1f}", f"{100 * (a['share'] - 1):+.1f}"])
            undefined = ~np.isfinite(by)
            if undefined.any():
                out.append([name, "undefined", fmt(int(undefined.sum())), "-",
                            fmt(100 * float(np.median(np.abs(rel7[undefined])))),
                            f"{100 * float(np.median(rel7[undefined])):+.1f}", "-",
                            f"{100 * float(np.median(rel8[undefined])):+.1f}", "-"])
            out.append([name, "all", fmt(int(sel.sum())), f"{np.nanmedian(by):.2f}",
                        fmt(100 * float(np.median(np.abs(rel7)))), f"{100 * float(np.median(rel7)):+.1f}",
                        fmt(100 * float(np.nanmedian(np.abs(rel7 * by)))), f"{100 * float(np.median(rel8)):+.1f}", "-"])
    return rows, split_rows, filter_rows, {"same": same}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="slider,wobble_slider,tracking_slider,pan")
    parser.add_argument("--duration", type=float, default=1.0, help="seconds per scenario (default 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", default="240x180")
    parser.add_argument("--pixels", choices=("default", "esim"), default="default",
                        help="esim: ESIM's example pixels (C 0.5, no threshold mismatch), smaller timing errors")
    parser.add_argument("--gyro-noise", type=float, default=1.5e-4,
                        help="noisy gyro: white noise density, rad/s/sqrt(Hz) (default 1.5e-4, ~0.009 deg/s/sqrt(Hz))")
    parser.add_argument("--gyro-bias", type=float, default=0.005,
                        help="noisy gyro: bias on every axis, rad/s (default 0.005, ~0.3 deg/s)")
    parser.add_argument("--cache", default=str(default_cache()), help="simulation cache folder ('' = none)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rows, split_rows, filter_rows, checks = [], [], [], []
    for name in [s for s in args.scenarios.split(",") if s]:
        log(f"{name}:")
        r, s, f, c = study(name, args)
        rows += r
        split_rows += s
        filter_rows += f
        checks.append(c["same"])
    print(f"Rotation study: {args.duration:g} s per scenario, seed {args.seed}, {args.size}, {args.pixels} pixels, "
          f"1 ms steps, 8-bit counters, per-pixel A t; noisy gyro {args.gyro_noise:g} rad/s/sqrt(Hz), "
          f"bias {args.gyro_bias:g} rad/s")
    print(f"eq. 8 recomputed from the tot spikes equals the network's output: {all(checks)}")
    print()
    print(text_table(["scenario", "depth from", "estimates", "coverage %", "median |rel| %", "median rel %",
                      "rejected r <= r_min"], rows))
    print()
    header = ["scenario", "r", "estimates", "median r", "eq. 7 |rel| %", "eq. 7 rel %", "|rel|*r %", "eq. 8 rel %",
              "r - 1 %"]
    print("eq. 7 (poses, interval) by the true translational share r (true depth and motion, measured td direction;")
    print("undefined: the true flow does not move along the measured td)")
    print("e / r law: |rel|*r flat across bins; eq. 8's bias is r - 1")
    print(text_table(header, split_rows))
    print()
    print("the same estimates by the share a depth neuron computes, r = 1 - (B w).td with the measured td "
          "(what min_share filters on)")
    print(text_table(header, filter_rows))
    print()
    cmd = reproduce("rotation_study.py", [("--scenarios", args.scenarios, "slider,wobble_slider,tracking_slider,pan"),
                                          ("--duration", args.duration, 1.0), ("--seed", args.seed, 0),
                                          ("--size", args.size, "240x180"), ("--pixels", args.pixels, "default"),
                                          ("--gyro-noise", args.gyro_noise, 1.5e-4),
                                          ("--gyro-bias", args.gyro_bias, 0.005)])
    print(f"{cmd}   ({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
