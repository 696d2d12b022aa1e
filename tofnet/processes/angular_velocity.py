"""AngularVelocityProcess: the camera's rotational flow ``B ω`` for the depth layer (paper eq. 7, computed off-chip)."""

from __future__ import annotations

from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var
from tofnet.errors import DataError, NetworkError
from tofnet.io.rotation import rotation_matrix

SOURCES = ("groundtruth", "gyro", "samples", "constant")
#: Parameters that only a gyroscope uses.
GYRO_PARAMS = ("imu", "rotation_cam_imu", "time_shift", "bias")


class AngularVelocityProcess(Process):
    """Sends the camera's angular velocity ``ω`` (rad/s, camera frame) every ``update_every`` steps.

    Receivers evaluate the rotational flow ``B ω`` (px/s) at every pixel (never per patch:
    it grows with ``x²``, ``y²`` and ``x y``), with ``x = u − cx``, ``y = v − cy``:
    ``(B ω)_u = (x y / fy) ωx − (fx + x²/fx) ωy + (fx/fy) y ωz``,
    ``(B ω)_v = (fy + y²/fy) ωx − (x y / fx) ωy − (fy/fx) x ωz``. Connected to a depth
    process's ``b_w``, it turns eq. 8 into eq. 7 (docs/semantics.md).

    ``ω`` comes from ground-truth poses (the derivative of their slerp), a gyroscope
    (``imu.txt``: ``ω = R_cam_imu (g(t + time_shift) − bias)``), samples (``t wx wy wz``
    per line) or a constant. Update ``j`` is sent in step ``j * update_every`` and samples
    ``ω`` at the start of that step. Intrinsics come from the recording's calibration
    unless given as ``intrinsics: [fx, fy, cx, cy]``.
    """

    outports = (PortSpec("b_w", Payload.ROTATION_TERM, 2, "B ω per pixel, px/s"),)
    params = (
        Param("source", "str", "groundtruth", doc="where the angular velocity comes from", choices=SOURCES),
        Param("omega", "vector3", None, unit="rad/s", optional=True,
              doc="constant camera-frame angular velocity [wx, wy, wz] (source: constant)"),
        Param("samples", "str", None, optional=True, reads_file=True,
              doc="file of 't wx wy wz' lines, seconds and rad/s in the camera frame (source: samples)"),
        Param("imu", "str", None, optional=True, reads_file=True,
              doc="an imu.txt file ('t ax ay az gx gy gz'); the recording's when omitted (source: gyro)"),
        Param("rotation_cam_imu", "floats", None, optional=True,
              doc="rotation taking IMU-frame vectors to the camera frame: 9 numbers (3x3, row by row) or a "
                  "quaternion [qx, qy, qz, qw]; identity when omitted (source: gyro)"),
        Param("time_shift", "duration", 0.0, unit="s",
              doc="Kalibr's timeshift_cam_imu: t_imu = t_cam + time_shift (source: gyro)"),
        Param("bias", "vector3", (0.0, 0.0, 0.0), unit="rad/s",
              doc="gyroscope bias in the IMU frame, subtracted from every sample (source: gyro)"),
        Param("update_every", "int", 1, unit="steps", doc="steps between two updates", minimum=1),
        Param("intrinsics", "floats", None, unit="px", optional=True,
              doc="[fx, fy, cx, cy]; from the recording's calibration when omitted"),
    )
    vars = (Var("last_omega", "vector", "float64", "rad/s", "angular velocity of the last update sent (NaN before "
                "the first)", channels=3),)
    placement = "host"

    def field_layout(self, port: str) -> tuple[int, int]:
        """A value per pixel (``B ω`` is never shared by a patch), every ``update_every`` steps."""
        return (1, int(self.update_every))

    def _check(self) -> None:
        values = self._values
        source = values["source"]
        if source == "constant" and values["omega"] is None:
            raise NetworkError(f"{self.name}: source 'constant' needs omega: [wx, wy, wz] in rad/s")
        if source == "samples" and values["samples"] is None:
            raise NetworkError(f"{self.name}: source 'samples' needs samples: a file of 't wx wy wz' lines")
        if source != "gyro":
            given = [name for name in GYRO_PARAMS if values[name] != self._default(name)]
            if given:
                raise NetworkError(f"{self.name}: {', '.join(given)} apply to source: gyro only (source is {source!r})")
        if values["rotation_cam_imu"] is not None:
            try:
                rotation_matrix(values["rotation_cam_imu"], f"{self.name}.rotation_cam_imu")
            except DataError as err:
                raise NetworkError(str(err)) from None
        if values["intrinsics"] is not None and len(values["intrinsics"]) != 4:
            raise NetworkError(f"{self.name}.intrinsics: expected [fx, fy, cx, cy], got {list(values['intrinsics'])}")

    @classmethod
    def _default(cls, name: str):
        param = next(p for p in cls.params if p.name == name)
        return param.coerce(param.default, cls.__name__)
