"""What one simulation needs: scene, trajectory, camera and pixel parameters (plain data)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from tofnet.io.recording import Intrinsics
from tofnet.sim.camera import DEFAULT_INTRINSICS, DEFAULT_SENSOR_SIZE, Trajectory, check_sensor_size, scaled_intrinsics
from tofnet.sim.errors import SimError
from tofnet.sim.rotation import ImuModel, RotatingTrajectory
from tofnet.sim.scene import Scene


OCCLUSION_DEPTHS = ("nearest_in_time", "nearer_surface")


#: Longest simulation (s): an hour of a busy scene is billions of events.
MAX_DURATION_S = 3600.0

@dataclass(frozen=True)
class SimConfig:
    """A simulation, ready to run with ``tofnet.sim.generate`` or ``tofnet.sim.simulate``.

    Parameters
    ----------
    name : label written in summaries.
    scene, trajectory : what is seen and how the camera moves (m, s); a ``RotatingTrajectory``
        also turns the camera.
    duration : seconds simulated from t = 0.
    intrinsics, sensor_size : pinhole camera (pixels) and ``(width, height)``.
    contrast_on, contrast_off : mean log-intensity thresholds C+ and C-.
    contrast_sigma : per-pixel standard deviation of both thresholds (fixed pattern).
    noise_rate : background-activity events per pixel per second (0 = none).
    pose_rate : ground-truth poses per second written to ``groundtruth.txt``.
    max_step_px : largest image motion between two renders, pixels.
    occlusion_depth : true depth of an event where an occluding contour crossed the pixel
        between two renders: ``"nearest_in_time"`` (the render nearer to the event) or
        ``"nearer_surface"`` (the occluding surface, whose motion made the event).
    imu : an ``ImuModel`` writes ``imu.txt`` (gyroscope and accelerometer); None: no IMU.
    description : one line for ``--list`` and the docs.
    """

    name: str
    scene: Scene
    trajectory: Trajectory | RotatingTrajectory
    duration: float = 1.0
    intrinsics: Intrinsics = DEFAULT_INTRINSICS
    sensor_size: tuple[int, int] = DEFAULT_SENSOR_SIZE
    contrast_on: float = 0.2
    contrast_off: float = 0.2
    contrast_sigma: float = 0.03
    noise_rate: float = 0.0
    pose_rate: float = 1000.0
    max_step_px: float = 0.25
    occlusion_depth: str = "nearest_in_time"
    imu: ImuModel | None = None
    description: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        check_sensor_size(self.sensor_size)
        if isinstance(self.duration, (int, float)) and self.duration > MAX_DURATION_S:
            raise SimError(f"duration: expected at most {MAX_DURATION_S:g} s, got {self.duration!r}")
        positive = {"duration": self.duration, "contrast_on": self.contrast_on, "contrast_off": self.contrast_off,
                     "pose_rate": self.pose_rate, "max_step_px": self.max_step_px}
        for key, value in positive.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SimError(f"{key}: expected a positive number, got {value!r}")
        for key, value in {"contrast_sigma": self.contrast_sigma, "noise_rate": self.noise_rate}.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise SimError(f"{key}: expected a number >= 0, got {value!r}")
        if self.occlusion_depth not in OCCLUSION_DEPTHS:
            raise SimError(f"occlusion_depth: expected one of {', '.join(OCCLUSION_DEPTHS)}, "
                           f"got {self.occlusion_depth!r}")
        if self.imu is not None and not isinstance(self.imu, ImuModel):
            raise SimError(f"imu: expected an ImuModel or None, got {type(self.imu).__name__}")
        if not (self.intrinsics.fx > 0 and self.intrinsics.fy > 0):
            raise SimError(f"intrinsics: expected positive focal lengths in pixels, got {self.intrinsics!r}")

    def replace(self, **changes) -> SimConfig:
        """A copy with ``changes``; ``sensor_size`` rescales the intrinsics to keep the field of view."""
        if "sensor_size" in changes and "intrinsics" not in changes:
            size = check_sensor_size(changes["sensor_size"])
            changes["sensor_size"] = size
            changes["intrinsics"] = scaled_intrinsics(self.intrinsics, self.sensor_size, size)
        return dataclasses.replace(self, **changes)
