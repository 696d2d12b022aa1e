"""A recording: events plus what is known about the camera that made them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from tofnet.errors import DataError
from tofnet.events import EVENT_DTYPE


#: Below this focal length (px) no lens images a sensor: the values are normalised intrinsics, not pixels.
MIN_FOCAL_PX = 1.0


def focal_problem(fx: float, fy: float) -> str | None:
    """What is wrong with focal lengths ``fx``, ``fy`` (pixels), or None; for one-line errors."""
    if fx <= 0 or fy <= 0:
        return f"focal lengths must be positive (pixels), got fx {fx:g}, fy {fy:g}"
    if fx < MIN_FOCAL_PX or fy < MIN_FOCAL_PX:
        return f"focal lengths of fx {fx:g}, fy {fy:g} px are below 1 px: normalised intrinsics? (expected pixels)"
    return None


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels and the lens distortion (OpenCV conventions).

    ``distortion_model`` ``"radtan"``: ``distortion`` is (k1, k2, p1, p2, k3) as in ECD
    ``calib.txt`` and ROS ``plumb_bob``; ``"equidistant"`` (OpenCV fisheye, Kannala-Brandt,
    DSEC and M3ED): (k1, k2, k3, k4). An empty ``distortion`` means none.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()
    distortion_model: str = "radtan"


class VelocitySource(Protocol):
    """Anything that gives the camera's translational velocity in the camera frame."""

    def velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Velocity (m/s, camera frame, shape ``(n, 3)``) at times ``t`` (seconds)."""
        ...


@dataclass(frozen=True)
class ConstantVelocity:
    """A camera moving at one velocity ``(tx, ty, tz)`` m/s in the camera frame."""

    velocity: tuple[float, float, float]

    def velocity_at(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        return np.broadcast_to(np.asarray(self.velocity, dtype=np.float64), (t.shape[0], 3)).copy()


def as_velocity_source(value, what: str = "velocity_source") -> VelocitySource:
    """``value`` as a ``VelocitySource``: one already (anything with ``velocity_at``), or three numbers
    ``(tx, ty, tz)`` m/s in the camera frame (a ``ConstantVelocity``); else a one-line ``DataError``."""
    if callable(getattr(value, "velocity_at", None)):
        return value
    try:
        numbers = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        numbers = ()
    if len(numbers) == 3 and all(np.isfinite(numbers)):
        return ConstantVelocity(numbers)
    raise DataError(f"{what}: expected a VelocitySource (with velocity_at) or (tx, ty, tz) in m/s, "
                    f"got {type(value).__name__} {value!r:.60}")


@dataclass
class Recording:
    """Events (``EVENT_DTYPE``, sorted by time) and optional calibration and ground truth.

    ``trajectory`` is the ground-truth camera motion (a ``VelocitySource``, usually
    built from ECD ``groundtruth.txt``); ``gt_depth`` the true depth of each event in
    metres (simulated recordings), aligned with ``events``; ``frame_gt`` ground-truth depth as
    frames (``tofnet.io.frames.FrameDepth``: dataset sequences), which ``tofnet eval`` scores
    estimates against at their own pixel and time.
    """

    events: np.ndarray
    intrinsics: Intrinsics | None = None
    trajectory: VelocitySource | None = None
    sensor_size: tuple[int, int] | None = None
    gt_depth: np.ndarray | None = None
    imu: np.ndarray | None = None
    source: str = "<memory>"
    notes: list[str] = field(default_factory=list)
    frame_gt: object | None = None

    def __post_init__(self) -> None:
        if self.events.dtype != EVENT_DTYPE:
            raise TypeError(f"{self.source}: events must have dtype {EVENT_DTYPE}, got {self.events.dtype}")
        if self.gt_depth is not None and len(self.gt_depth) != len(self.events):
            raise ValueError(f"{self.source}: {len(self.gt_depth)} ground-truth depths for {len(self.events)} events")

    @property
    def duration(self) -> float:
        """Seconds from the first to the last event (0 for fewer than two)."""
        if len(self.events) < 2:
            return 0.0
        return float(self.events["t"][-1] - self.events["t"][0]) * 1e-6
