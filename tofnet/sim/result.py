"""What both simulation engines build: the result, its growable event buffers, the noise
events and the final time-sorted merge (``engine.py`` translates, ``engine_rotating.py`` turns)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Intrinsics, Recording
from tofnet.sim.config import SimConfig

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


class EventBuffers:
    """Growable event columns (``t`` µs, ``x``, ``y``, ``p``, ``d`` true depth m); ``n`` in use."""

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


def noise_events(config: SimConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Background-activity events: a Poisson process per pixel, random polarity; sorted by time (s).

    Returns ``(t s, pixel index, polarity, depth m)``; the depths are left for the engine
    to fill (interpolated between the renders around each event).
    """
    width, height = config.sensor_size
    count = int(rng.poisson(config.noise_rate * width * height * config.duration)) if config.noise_rate > 0 else 0
    t = np.sort(rng.uniform(0.0, config.duration, size=count))
    pixel = rng.integers(0, width * height, size=count)
    p = rng.integers(0, 2, size=count).astype(np.uint8)
    return t, pixel, p, np.empty(count, dtype=np.float32)


def merge_events(buf: EventBuffers, noise_t, noise_pixel, noise_p, noise_d,
                 width: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Contrast and noise events in one array, stably sorted by time; ties keep generation order.

    Returns ``(events, gt_depth, number of contrast events)``.
    """
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


def pose_times(config: SimConfig) -> np.ndarray:
    """Times (s) of the recorded poses: every ``1 / pose_rate`` from 0 to the duration."""
    return np.arange(int(np.floor(config.duration * config.pose_rate + 1e-9)) + 1) / config.pose_rate
