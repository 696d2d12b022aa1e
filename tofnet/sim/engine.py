"""Run a simulation: render the scene along the trajectory and turn the renders into events."""

from __future__ import annotations

import time

import numpy as np

from tofnet.sim.config import SimConfig
from tofnet.sim.dvs import DEPTH_JUMP, count_crossings, emit_crossings, thresholds
from tofnet.sim.engine_rotating import generate_rotating
from tofnet.sim.errors import SimError
from tofnet.sim.lens import pixel_rays
from tofnet.sim.render import Renderer, max_flow, render_times
from tofnet.sim.result import EventBuffers, Progress, SimResult, merge_events, noise_events, pose_times
from tofnet.sim.rotation import imu_samples
from tofnet.sim.scene import pack_scene

__all__ = ["Progress", "SimResult", "generate"]


def generate(config: SimConfig, *, seed: int = 0, progress: Progress | None = None) -> SimResult:
    """Simulate ``config`` and return events with per-event ground-truth depth.

    Everything random (textures, thresholds, noise) comes from ``seed``: the same
    config and seed give identical events. ``seed`` is a whole number >= 0. A turning
    camera (``config.trajectory.rotates``) is simulated by ``tofnet.sim.engine_rotating``.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SimError(f"seed: expected a whole number >= 0, got {seed!r}")
    if getattr(config.trajectory, "rotates", False):
        return generate_rotating(config, seed=seed, progress=progress)
    start = time.perf_counter()
    k = config.intrinsics
    width, height = config.sensor_size
    npix = width * height
    traj = config.trajectory
    # Positions are piecewise linear: their extremes are at segment boundaries or the ends.
    corners = np.concatenate([[0.0, config.duration], traj.boundaries[traj.boundaries < config.duration]])
    poses = traj.position_at(corners)
    rays = pixel_rays(k, config.sensor_size)  # a pinhole, or the lens's distortion (tofnet.sim.lens)
    scene = pack_scene(config.scene, focal=max(k.fx, k.fy), camera_box=(poses.min(axis=0), poses.max(axis=0)),
                       fov=rays.fov, seed=seed)
    renderer = Renderer(scene, k, config.sensor_size, rays)
    times = render_times(traj, config.duration, scene.min_z, k, config.sensor_size, config.max_step_px, rays)
    positions = traj.position_at(times)
    velocities = traj.velocity_at(0.5 * (times[:-1] + times[1:])) if times.size > 1 else np.zeros((0, 3))

    threshold_rng, noise_rng = (np.random.default_rng([seed, 104729, i]) for i in range(2))
    c_on = thresholds(npix, config.contrast_on, config.contrast_sigma, threshold_rng)
    c_off = thresholds(npix, config.contrast_off, config.contrast_sigma, threshold_rng)
    noise_t, noise_pixel, noise_p, noise_d = noise_events(config, noise_rng)
    noise_cut = np.searchsorted(noise_t, times, side="left")

    log0, depth0 = renderer.render(positions[0])
    ref = log0.copy()
    buf = EventBuffers(max(1 << 16, 4 * npix))
    max_step = 0.0
    last_report = time.perf_counter()
    for i in range(times.size - 1):
        log1, depth1 = renderer.render(positions[i + 1])
        vx, vy, vz = velocities[i]
        span = times[i + 1] - times[i]
        # The image step actually taken, from the rendered depths at both ends.
        # (through a distorted lens: the pinhole flow at the pixels, times the lens's largest magnification)
        step = span * rays.flow_scale * max(max_flow(depth0, vx, vy, vz, k.fx, k.fy, k.cx, k.cy, width),
                                            max_flow(depth1, vx, vy, vz, k.fx, k.fy, k.cx, k.cy, width))
        max_step = max(max_step, step)
        buf.reserve(count_crossings(log0, log1, ref, c_on, c_off))
        buf.n = emit_crossings(log0, log1, depth0, depth1, ref, c_on, c_off, times[i] * 1e6, times[i + 1] * 1e6,
                               width, DEPTH_JUMP, config.occlusion_depth == "nearer_surface", buf.t, buf.x, buf.y, buf.p, buf.d, buf.n)
        a, b = noise_cut[i], noise_cut[i + 1]
        if b > a:
            frac = (noise_t[a:b] - times[i]) / span
            pix = noise_pixel[a:b]
            noise_d[a:b] = depth0[pix] + frac * (depth1[pix] - depth0[pix])
        log0, depth0 = log1, depth1
        if progress is not None and time.perf_counter() - last_report > 0.1:
            last_report = time.perf_counter()
            progress(i + 1, times.size - 1)

    events, gt_depth, n_contrast = merge_events(buf, noise_t, noise_pixel, noise_p, noise_d, width)
    times_of_poses = pose_times(config)
    quaternions = np.zeros((times_of_poses.size, 4))
    quaternions[:, 3] = 1.0  # no rotation: identity (qx qy qz qw)
    stats = {"renders": int(times.size), "max_render_step_px": float(max_step), "contrast_events": n_contrast,
             "noise_events": int(noise_t.size), "faces": len(scene.names),
             "wall_time_s": time.perf_counter() - start}
    return SimResult(config=config, seed=seed, events=events, gt_depth=gt_depth, pose_times=times_of_poses,
                     positions=traj.position_at(times_of_poses), quaternions=quaternions, stats=stats,
                     imu=imu_samples(config, seed))

