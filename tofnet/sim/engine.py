"""Run a simulation: render the scene along the trajectory and turn the renders into events."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Intrinsics, Recording
from tofnet.sim.config import SimConfig
from tofnet.sim.errors import SimError
from tofnet.sim.lens import pixel_rays
from tofnet.sim.dvs import DEPTH_JUMP, count_crossings, emit_crossings, thresholds
from tofnet.sim.render import Renderer, max_flow, render_times
from tofnet.sim.rotation import imu_samples
from tofnet.sim.scene import pack_scene

#: ``progress(renders_done, renders_total)``, called at most ten times a second.
Progress = Callable[[int, int], None]


@dataclass
class SimResult:
    """Simulated events with ground truth.

    ``events`` (``EVENT_DTYPE``, sorted by time), ``gt_depth`` (float32 m, one per
    event: camera-frame z of the surface at that pixel and time), poses sampled at
    ``config.pose_rate`` (``pose_times`` s, ``positions`` m, ``quaternions`` qx qy qz qw,
    identity unless the camera turns), ``stats`` (renders, ``max_render_step_px``, wall
    time ...) and ``imu`` (``imu.txt`` rows ``t ax ay az gx gy gz``, or None).
    """

    config: SimConfig
    seed: int
    events: np.ndarray
    gt_depth: np.ndarray
    pose_times: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray
    stats: dict = field(default_factory=dict)
    imu: np.ndarray | None = None

    @property
    def intrinsics(self) -> Intrinsics:
        return self.config.intrinsics

    @property
    def sensor_size(self) -> tuple[int, int]:
        return self.config.sensor_size

    def to_recording(self) -> Recording:
        """The result as a ``Recording`` (trajectory = the exact piecewise-constant velocity)."""
        return Recording(events=self.events, intrinsics=self.intrinsics, trajectory=self.config.trajectory,
                         sensor_size=self.sensor_size, gt_depth=self.gt_depth.astype(np.float64), imu=self.imu,
                         source=f"sim:{self.config.name}:seed={self.seed}")


class _Buffers:
    """Growable event columns."""

    def __init__(self, capacity: int) -> None:
        self.n = 0
        self._alloc(capacity)

    def _alloc(self, capacity: int) -> None:
        old = getattr(self, "t", None)
        cols = {"t": np.int64, "x": np.uint16, "y": np.uint16, "p": np.uint8, "d": np.float32}
        for name, dtype in cols.items():
            new = np.empty(capacity, dtype=dtype)
            if old is not None:
                new[:self.n] = getattr(self, name)[:self.n]
            setattr(self, name, new)

    def reserve(self, extra: int) -> None:
        if self.n + extra > self.t.shape[0]:
            self._alloc(max(2 * self.t.shape[0], self.n + extra))


def _noise(config: SimConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Background-activity events: a Poisson process per pixel, random polarity; sorted by time (s)."""
    width, height = config.sensor_size
    count = int(rng.poisson(config.noise_rate * width * height * config.duration)) if config.noise_rate > 0 else 0
    t = np.sort(rng.uniform(0.0, config.duration, size=count))
    pixel = rng.integers(0, width * height, size=count)
    p = rng.integers(0, 2, size=count).astype(np.uint8)
    return t, pixel, p, np.empty(count, dtype=np.float32)


def generate(config: SimConfig, *, seed: int = 0, progress: Progress | None = None) -> SimResult:
    """Simulate ``config`` and return events with per-event ground-truth depth.

    Everything random (textures, thresholds, noise) comes from ``seed``: the same
    config and seed give identical events. ``seed`` is a whole number >= 0. A turning
    camera (``config.trajectory.rotates``) is simulated by ``tofnet.sim.engine_rotating``.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SimError(f"seed: expected a whole number >= 0, got {seed!r}")
    if getattr(config.trajectory, "rotates", False):
        from tofnet.sim.engine_rotating import generate_rotating  # it builds on this module
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
    noise_t, noise_pixel, noise_p, noise_d = _noise(config, noise_rng)
    noise_cut = np.searchsorted(noise_t, times, side="left")

    log0, depth0 = renderer.render(positions[0])
    ref = log0.copy()
    buf = _Buffers(max(1 << 16, 4 * npix))
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

    events, gt_depth, n_contrast = _merge(buf, noise_t, noise_pixel, noise_p, noise_d, width)
    pose_times = np.arange(int(np.floor(config.duration * config.pose_rate + 1e-9)) + 1) / config.pose_rate
    quaternions = np.zeros((pose_times.size, 4))
    quaternions[:, 3] = 1.0  # no rotation: identity (qx qy qz qw)
    stats = {"renders": int(times.size), "max_render_step_px": float(max_step), "contrast_events": n_contrast,
             "noise_events": int(noise_t.size), "faces": len(scene.names),
             "wall_time_s": time.perf_counter() - start}
    return SimResult(config=config, seed=seed, events=events, gt_depth=gt_depth, pose_times=pose_times,
                     positions=traj.position_at(pose_times), quaternions=quaternions, stats=stats,
                     imu=imu_samples(config, seed))


def _merge(buf: _Buffers, noise_t, noise_pixel, noise_p, noise_d, width: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Contrast and noise events in one array, stably sorted by time; ties keep generation order."""
    n = buf.n
    total = n + noise_t.size
    events = np.empty(total, dtype=EVENT_DTYPE)
    events["t"][:n], events["x"][:n], events["y"][:n], events["p"][:n] = buf.t[:n], buf.x[:n], buf.y[:n], buf.p[:n]
    events["t"][n:] = np.floor(noise_t * 1e6 + 0.5).astype(np.int64)
    events["x"][n:] = noise_pixel % width
    events["y"][n:] = noise_pixel // width
    events["p"][n:] = noise_p
    depth = np.concatenate([buf.d[:n], noise_d])
    order = np.argsort(events["t"], kind="stable")
    return events[order], depth[order], n
