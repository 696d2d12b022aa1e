"""The velocity process on every backend family: camera velocity updates for the ``velocity_term`` field."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.models.binding import UpdateRows, camera_of, velocity_source_of, velocity_table
from tofnet.errors import DataError
from tofnet.core.ports import Payload
from tofnet.io.recording import VelocitySource
from tofnet.kernels.lens import Lens, lens_of, sample_table
from tofnet.kernels.velocity import velocity_term
from tofnet.models.base import Model, ModelContext, records
from tofnet.processes import VelocityProcess

#: Updates computed ahead of the clock, so that a short run rarely asks the source.
LOOKAHEAD = 1024


def updates_between(first: int, end: int, update_every: int) -> tuple[int, int]:
    """``(j0, j1)``: the updates ``j`` whose step ``j * update_every`` lies in ``[first, end)``."""
    return -(-first // update_every), -(-end // update_every)


@dataclass(frozen=True)
class VelocityField:
    """How receivers turn a ``velocity_term`` update (camera velocity t, m/s) into ``A t`` (px*m/s).

    ``A t`` of pixel (x, y) is evaluated at the pixel (``per_pixel``) or at the centre of its
    ``patch_size`` square (patches tile the sensor from (0, 0)), with ``intrinsics``
    ``(fx, fy, cx, cy)`` px, through ``lens`` (``tofnet.kernels.lens``; None: a pinhole).
    """

    per_pixel: bool
    patch_size: int
    intrinsics: tuple[float, float, float, float]
    sensor_size: tuple[int, int]
    lens: Lens | None = None

    def dense(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``A t`` at every pixel: two ``(height, width)`` arrays (the reference models' view)."""
        s = sample_table(self.per_pixel, self.patch_size, tuple(self.sensor_size), tuple(self.intrinsics), self.lens)
        at_x, at_y = velocity_term(float(t[0]), float(t[1]), float(t[2]), s[..., 0], s[..., 1], *self.intrinsics)
        return s[..., 2] * at_x + s[..., 3] * at_y, s[..., 4] * at_x + s[..., 5] * at_y


def velocity_field(process: VelocityProcess, sensor_size: tuple[int, int], recording) -> VelocityField:
    """How ``process``'s updates become ``A t`` on a ``sensor_size`` px sensor, with the camera ``recording``
    (its metadata) describes (the models and the fused chain use this)."""
    camera = camera_of(process.intrinsics, process.distortion_model, process.distortion, recording, process.name)
    return VelocityField(process.per == "pixel", int(process.patch_size), (camera.fx, camera.fy, camera.cx, camera.cy),
                         tuple(sensor_size), lens_of(camera))


def velocity_source(process: VelocityProcess, recording) -> VelocitySource:
    """The camera velocity ``process`` reads (``recording``: its metadata, for ``groundtruth``)."""
    try:
        return velocity_source_of(process.source, process.velocity, process.samples, recording, process.name)
    except DataError as err:  # a bare event file lacks both: say so at once, not one run after the other
        if process.intrinsics is None and (recording is None or recording.intrinsics is None):
            raise DataError(f"{err}; the camera's calibration is missing too: also pass --intrinsics FX,FY,CX,CY "
                            "or --calib FILE") from None
        raise


class VelocityModel(Model):
    """Sends update ``j`` in step ``j * update_every``: the camera velocity at the start of that step."""

    def __init__(self, process: VelocityProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        self.source = velocity_source(process, ctx.recording)
        self.update_every = int(process.update_every)
        self.updates = UpdateRows(lambda first, count: velocity_table(
            self.source, ctx.t0_us, ctx.timestep_us, self.update_every, count, first), LOOKAHEAD)
        self._dtype = Payload.VELOCITY_TERM.dtype
        self._last = np.full(3, np.nan)

    @classmethod
    def output_meta(cls, process: VelocityProcess, ctx: ModelContext) -> dict:
        return {"a_t": velocity_field(process, ctx.sensor_size, ctx.recording)}

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        j0, j1 = updates_between(first, end, self.update_every)
        if j1 <= j0:
            return {"a_t": np.empty(0, self._dtype)}
        t = self.updates.slice(j0, j1 - j0)
        self._last = t[-1].copy()
        return {"a_t": records(self._dtype, step=np.arange(j0, j1, dtype=np.int64) * self.update_every,
                               tx=t[:, 0], ty=t[:, 1], tz=t[:, 2])}

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "last_velocity":
            return self._last.copy()
        return super().get_var(name, step)

    def set_param(self, name: str, value) -> None:
        if name == "velocity" and self.process.source == "constant":  # updates sent from now on
            self.source = velocity_source_of("constant", value, None, None, self.process.name)
            self.updates.clear()
            return
        super().set_param(name, value)
