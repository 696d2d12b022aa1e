"""The angular velocity process on every backend family: updates of the ``rotation_term`` field (paper eq. 7)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.models.binding import UpdateRows, angular_velocity_table, intrinsics_of
from tofnet.core.ports import Payload
from tofnet.errors import DataError
from tofnet.io.groundtruth import Trajectory
from tofnet.io.rotation import (AngularVelocitySource, ConstantAngularVelocity, PoseAngularVelocity,
                                gyroscope_from_imu, read_angular_velocity_samples, read_gyroscope, rotation_matrix)
from tofnet.kernels.rotation import rotational_flow_grid
from tofnet.models.base import Model, ModelContext, records
from tofnet.models.velocity import LOOKAHEAD, updates_between
from tofnet.processes import AngularVelocityProcess


@dataclass(frozen=True)
class RotationField:
    """How receivers turn a ``rotation_term`` update (``ω``, rad/s, camera frame) into ``B ω`` (px/s).

    ``B ω`` is evaluated at every pixel (``tofnet.kernels.rotation.rotational_flow``) with
    ``intrinsics`` ``(fx, fy, cx, cy)`` px; there is no per-patch sampling.
    """

    intrinsics: tuple[float, float, float, float]
    sensor_size: tuple[int, int]

    def dense(self, omega) -> tuple[np.ndarray, np.ndarray]:
        """``B ω`` at every pixel: two ``(height, width)`` arrays, px/s (the reference models' view)."""
        width, height = self.sensor_size
        return rotational_flow_grid(float(omega[0]), float(omega[1]), float(omega[2]), width, height,
                                    *self.intrinsics)


def angular_velocity_source_of(process: AngularVelocityProcess, recording) -> AngularVelocitySource:
    """The angular velocity ``process`` reads: a constant, a samples file, a gyroscope or the poses."""
    source = process.source
    where = recording.source if recording is not None else "the stream"
    if source == "constant":
        return ConstantAngularVelocity(tuple(process.omega))
    if source == "samples":
        return read_angular_velocity_samples(process.samples)
    if source == "gyro":
        rotation = process.rotation_cam_imu
        options = {"rotation_cam_imu": None if rotation is None else rotation_matrix(rotation),
                   "time_shift": process.time_shift, "bias": process.bias}
        if process.imu is not None:
            return read_gyroscope(process.imu, **options)
        if recording is None or recording.imu is None or not len(recording.imu):
            raise DataError(f"{where}: no IMU samples (imu.txt), but angular velocity process '{process.name}' "
                            "has source: gyro; add imu.txt, set imu: FILE, or use source: groundtruth/samples/constant")
        return gyroscope_from_imu(recording.imu, source=recording.source, **options)
    trajectory = recording.trajectory if recording is not None else None
    if hasattr(trajectory, "angular_velocity_at"):  # e.g. a simulated camera's exact motion
        return trajectory
    if isinstance(trajectory, Trajectory):
        return PoseAngularVelocity(trajectory)
    raise DataError(f"{where}: no ground-truth poses with orientations (groundtruth.txt), but angular velocity "
                    f"process '{process.name}' has source: groundtruth; add the poses or use source: "
                    "gyro/samples/constant")


class AngularVelocityModel(Model):
    """Sends update ``j`` in step ``j * update_every``: the angular velocity at the start of that step."""

    def __init__(self, process: AngularVelocityProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        self.source = angular_velocity_source_of(process, ctx.recording)
        self.update_every = int(process.update_every)
        self.updates = UpdateRows(lambda first, count: angular_velocity_table(
            self.source, ctx.t0_us, ctx.timestep_us, self.update_every, count, first), LOOKAHEAD)
        self._dtype = Payload.ROTATION_TERM.dtype
        self._last = np.full(3, np.nan)

    @classmethod
    def output_meta(cls, process: AngularVelocityProcess, ctx: ModelContext) -> dict:
        intr = intrinsics_of(process.intrinsics, ctx.recording, process.name)
        return {"b_w": RotationField((intr.fx, intr.fy, intr.cx, intr.cy), tuple(ctx.sensor_size))}

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        j0, j1 = updates_between(first, end, self.update_every)
        if j1 <= j0:
            return {"b_w": np.empty(0, self._dtype)}
        w = self.updates.slice(j0, j1 - j0)
        self._last = w[-1].copy()
        return {"b_w": records(self._dtype, step=np.arange(j0, j1, dtype=np.int64) * self.update_every,
                               wx=w[:, 0], wy=w[:, 1], wz=w[:, 2])}

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "last_omega":
            return self._last.copy()
        return super().get_var(name, step)

    def set_param(self, name: str, value) -> None:
        if name == "omega" and self.process.source == "constant":  # updates sent from now on
            self.source = angular_velocity_source_of(self.process, self.ctx.recording)
            self.updates.clear()
            return
        super().set_param(name, value)
