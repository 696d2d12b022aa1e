"""The simulated camera: pinhole intrinsics and a purely translational trajectory.

The camera never rotates (the paper's assumption), so its frame is the world frame
shifted by its position: a world point ``P`` is at ``P - c(t)`` in the camera frame
(OpenCV: x right, y down, z forward) and its depth is ``P_z - c_z(t)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tofnet.io.recording import Intrinsics
from tofnet.sim.errors import SimError

#: DAVIS240C-like sensor (width, height) in pixels.
DEFAULT_SENSOR_SIZE = (240, 180)
#: DAVIS240C-like pinhole intrinsics (pixels), rounded from the ECD DAVIS240C
#: calibration (e.g. ``slider_depth/calib.txt``), without its distortion (a pinhole; intrinsics
#: with distortion coefficients simulate that lens, ``tofnet.sim.lens``).
DEFAULT_INTRINSICS = Intrinsics(fx=199.1, fy=198.8, cx=132.2, cy=110.7)


def scaled_intrinsics(intrinsics: Intrinsics, base_size: tuple[int, int], size: tuple[int, int]) -> Intrinsics:
    """The same field of view on a sensor of ``size = (width, height)`` pixels.

    Each axis scales by ``size / base_size``; pixel centres are at integers, so the
    principal point maps as ``c' = (c + 0.5) * s - 0.5``. Distortion coefficients act on
    normalised coordinates and are kept.
    """
    sx, sy = size[0] / base_size[0], size[1] / base_size[1]
    return Intrinsics(fx=intrinsics.fx * sx, fy=intrinsics.fy * sy,
                      cx=(intrinsics.cx + 0.5) * sx - 0.5, cy=(intrinsics.cy + 0.5) * sy - 0.5,
                      distortion=intrinsics.distortion, distortion_model=intrinsics.distortion_model)


def check_sensor_size(size: object, what: str = "sensor_size") -> tuple[int, int]:
    """``size`` as ``(width, height)`` positive ints, or a ``SimError`` naming ``what``."""
    try:
        width, height = (int(v) for v in size)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise SimError(f"{what}: expected (width, height) in pixels, got {size!r}") from None
    if width < 2 or height < 2 or width > 65535 or height > 65535:
        raise SimError(f"{what}: expected width and height between 2 and 65535 pixels, got {width}x{height}")
    from tofnet.events import sensor_size_problem
    problem = sensor_size_problem(width, height)
    if problem:
        raise SimError(f"{what}: {problem}")
    return width, height


@dataclass(frozen=True)
class Segment:
    """``duration`` seconds of constant translational ``velocity`` (m/s, camera = world frame)."""

    duration: float
    velocity: tuple[float, float, float]


@dataclass(frozen=True)
class Trajectory:
    """Piecewise-constant velocity: the camera starts at ``start`` (m, world) at t = 0 s.

    After the last segment the camera stands still. Velocities are right-continuous:
    at a segment boundary the new segment's velocity applies. Implements the
    ``VelocitySource`` protocol of ``tofnet.io.recording``.
    """

    start: tuple[float, float, float]
    segments: tuple[Segment, ...]

    def __post_init__(self) -> None:
        if len(self.start) != 3 or not all(math.isfinite(v) for v in self.start):
            raise SimError(f"trajectory start: expected 3 finite coordinates in metres, got {self.start!r}")
        for i, seg in enumerate(self.segments):
            if not (math.isfinite(seg.duration) and seg.duration > 0):
                raise SimError(f"trajectory segment {i} duration: expected a positive number of seconds, "
                               f"got {seg.duration!r}")
            if len(seg.velocity) != 3 or not all(math.isfinite(v) for v in seg.velocity):
                raise SimError(f"trajectory segment {i} velocity: expected 3 finite m/s values, got {seg.velocity!r}")

    @property
    def boundaries(self) -> np.ndarray:
        """Segment start times and the end of the last one, seconds."""
        return np.concatenate([[0.0], np.cumsum([s.duration for s in self.segments])])

    def _knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        bounds = self.boundaries
        vel = np.array([s.velocity for s in self.segments] + [(0.0, 0.0, 0.0)], dtype=np.float64).reshape(-1, 3)
        steps = vel[:-1] * np.diff(bounds)[:, None]
        pos = np.concatenate([np.asarray(self.start, dtype=np.float64)[None], steps]).cumsum(axis=0)
        return bounds, vel, pos

    def segment_index(self, t: np.ndarray) -> np.ndarray:
        """Index of the segment holding each time (``len(segments)`` after the end)."""
        bounds = self.boundaries
        return np.clip(np.searchsorted(bounds, np.asarray(t, dtype=np.float64), side="right") - 1, 0,
                       len(self.segments))

    def velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Velocity (m/s, shape ``(n, 3)``) at times ``t`` (seconds)."""
        _, vel, _ = self._knots()
        return vel[self.segment_index(np.atleast_1d(t))].copy()

    def position_at(self, t: np.ndarray) -> np.ndarray:
        """Camera position (m, world, shape ``(n, 3)``) at times ``t`` (seconds, t >= 0)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        bounds, vel, pos = self._knots()
        k = self.segment_index(t)
        return pos[k] + vel[k] * (t - bounds[k])[:, None]


def constant(velocity: tuple[float, float, float], duration: float,
             start: tuple[float, float, float] | None = None) -> Trajectory:
    """One segment; by default centred so the camera passes the origin at ``duration / 2``."""
    if start is None:
        start = tuple(-0.5 * duration * v for v in velocity)  # type: ignore[assignment]
    return Trajectory(start=tuple(float(v) for v in start), segments=(Segment(duration, tuple(velocity)),))
