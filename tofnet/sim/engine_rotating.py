"""Simulating a turning camera (``RotatingTrajectory``): renders paced by the image motion they measure.

The translational engine bounds the image speed a priori (``flow_bound`` with the
scene's nearest depth); a turning camera sees points nearer than that bound allows
and adds the rotational flow ``B ω``. So each next render time here follows from the
speed ``|A t / Z + B ω|`` measured on the last render's depths (with a safety factor),
and an interval whose measured step (the larger speed at its two ends times its
length) exceeds ``max_step_px`` is halved and rendered again. Pixels, noise and events
are the translational engine's (same seeds, same rules).
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit

from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.velocity import velocity_term
from tofnet.sim.config import SimConfig
from tofnet.sim.dvs import DEPTH_JUMP, count_crossings, emit_crossings, thresholds
from tofnet.sim.errors import SimError
from tofnet.sim.render import Renderer
from tofnet.sim.rotation import imu_samples
from tofnet.sim.result import EventBuffers, Progress, SimResult, merge_events, noise_events, pose_times
from tofnet.sim.scene import pack_scene

#: The next interval is ``max_step_px / (SAFETY * speed now)`` long.
SAFETY = 1.25
#: Longest interval between renders, s (the image may speed up between two renders).
MAX_SPAN = 0.005
#: Halving stops here (s); an interval this short is kept whatever its step.
MIN_SPAN = 1e-7


@njit(cache=True)
def max_image_speed(depth, vx, vy, vz, wx, wy, wz, fx, fy, cx, cy, width):  # pragma: no cover - numba
    """Largest image speed (px/s) over pixels: ``|A t / Z + B ω|`` (camera-frame ``t`` m/s, ``ω`` rad/s)."""
    best = 0.0
    for i in range(depth.shape[0]):
        u = float(i % width)
        v = float(i // width)
        au, av = velocity_term(vx, vy, vz, u, v, fx, fy, cx, cy)
        bu, bv = rotational_flow(wx, wy, wz, u, v, fx, fy, cx, cy)
        su = au / depth[i] + bu
        sv = av / depth[i] + bv
        s = math.sqrt(su * su + sv * sv)
        if s > best:
            best = s
    return best


def rotated_fov(trajectory, times: np.ndarray, intrinsics, sensor_size) -> tuple[float, float, float, float]:
    """World ray slopes ``(left, right, top, bottom)`` (x/z, y/z) of the sensor's edges over every orientation."""
    k = intrinsics
    width, height = sensor_size
    us = np.array([-0.5, (width - 1) / 2, width - 0.5])
    vs = np.array([-0.5, (height - 1) / 2, height - 0.5])
    rays = np.array([[(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0] for u in us for v in vs])
    world = np.einsum("nij,rj->nri", trajectory.rotation_at(times), rays).reshape(-1, 3)
    if np.any(world[:, 2] <= 0.05):
        raise SimError("trajectory: the camera turns so far that the sensor's edge rays point sideways or back; "
                       "expected it to keep looking forward (+z) within about 85 degrees")
    sx, sy = world[:, 0] / world[:, 2], world[:, 1] / world[:, 2]
    return float(sx.min()), float(sx.max()), float(sy.min()), float(sy.max())


def generate_rotating(config: SimConfig, *, seed: int = 0, progress: Progress | None = None) -> SimResult:
    """``tofnet.sim.engine.generate`` for a turning camera (``config.trajectory.rotates``)."""
    start = time.perf_counter()
    k = config.intrinsics
    if any(c != 0 for c in k.distortion):
        raise SimError("intrinsics: lens distortion is simulated for translating cameras only; expected no "
                       "distortion coefficients with a turning camera")
    width, height = config.sensor_size
    npix = width * height
    traj = config.trajectory
    bounds = traj.boundaries
    probe = np.unique(np.concatenate([np.linspace(0.0, config.duration, 401), bounds[bounds < config.duration]]))
    poses = traj.position_at(probe)
    scene = pack_scene(config.scene, focal=max(k.fx, k.fy), camera_box=(poses.min(axis=0), poses.max(axis=0)),
                       fov=rotated_fov(traj, probe, k, config.sensor_size), seed=seed)
    renderer = Renderer(scene, k, config.sensor_size)

    threshold_rng, noise_rng = (np.random.default_rng([seed, 104729, i]) for i in range(2))
    c_on = thresholds(npix, config.contrast_on, config.contrast_sigma, threshold_rng)
    c_off = thresholds(npix, config.contrast_off, config.contrast_sigma, threshold_rng)
    noise_t, noise_pixel, noise_p, noise_d = noise_events(config, noise_rng)
    stops = np.unique(np.concatenate([bounds[(bounds > 0) & (bounds < config.duration)], [config.duration]]))

    def render(t: float):
        return renderer.render(traj.position_at(t)[0], traj.rotation_at(t)[0])

    def speed(depth, t: float) -> float:
        v, w = traj.velocity_at(t)[0], traj.angular_velocity_at(t)[0]
        return max_image_speed(depth, v[0], v[1], v[2], w[0], w[1], w[2], k.fx, k.fy, k.cx, k.cy, width)

    t0 = 0.0
    log0, depth0 = render(t0)
    ref = log0.copy()
    buf = EventBuffers(max(1 << 16, 4 * npix))
    renders, max_step, last_report = 1, 0.0, time.perf_counter()
    while t0 < config.duration:
        speed0 = speed(depth0, t0)
        stop = float(stops[np.searchsorted(stops, t0, side="right")])
        span = min(MAX_SPAN, config.max_step_px / (SAFETY * speed0) if speed0 > 0 else MAX_SPAN)
        while True:
            t1 = stop if t0 + span >= stop else t0 + span
            log1, depth1 = render(t1)
            renders += 1
            step = (t1 - t0) * max(speed0, speed(depth1, t1))
            if step <= config.max_step_px or t1 - t0 <= MIN_SPAN:
                break
            span = 0.5 * (t1 - t0)
        max_step = max(max_step, step)
        buf.reserve(count_crossings(log0, log1, ref, c_on, c_off))
        buf.n = emit_crossings(log0, log1, depth0, depth1, ref, c_on, c_off, t0 * 1e6, t1 * 1e6, width, DEPTH_JUMP,
                               config.occlusion_depth == "nearer_surface", buf.t, buf.x, buf.y, buf.p, buf.d, buf.n)
        a, b = np.searchsorted(noise_t, [t0, t1], side="left")
        if b > a:
            frac = (noise_t[a:b] - t0) / (t1 - t0)
            pix = noise_pixel[a:b]
            noise_d[a:b] = depth0[pix] + frac * (depth1[pix] - depth0[pix])
        t0, log0, depth0 = t1, log1, depth1
        if progress is not None and time.perf_counter() - last_report > 0.1:
            last_report = time.perf_counter()
            # The render count is not known in advance: extrapolated from the time simulated so far.
            progress(renders, max(renders, int(renders * config.duration / t0)))

    events, gt_depth, n_contrast = merge_events(buf, noise_t, noise_pixel, noise_p, noise_d, width)
    times_of_poses = pose_times(config)
    stats = {"renders": renders, "max_render_step_px": float(max_step), "contrast_events": n_contrast,
             "noise_events": int(noise_t.size), "faces": len(scene.names), "wall_time_s": time.perf_counter() - start}
    return SimResult(config=config, seed=seed, events=events, gt_depth=gt_depth, pose_times=times_of_poses,
                     positions=traj.position_at(times_of_poses), quaternions=traj.quaternion_at(times_of_poses), stats=stats,
                     imu=imu_samples(config, seed))
