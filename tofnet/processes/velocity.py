"""VelocityProcess: the camera's velocity term ``A t`` for the depth layer (computed off-chip)."""

from __future__ import annotations

from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var
from tofnet.errors import NetworkError
from tofnet.processes.undistort import COEFFICIENTS, MODELS

SOURCES = ("groundtruth", "samples", "constant")
#: Lens models (OpenCV conventions, ``tofnet.kernels.undistort``), and ``none`` for a pinhole.
DISTORTION_MODELS = MODELS + ("none",)


class VelocityProcess(Process):
    """Sends ``A t = (-fx*tx + (u-cx)*tz, -fy*ty + (v-cy)*tz)`` (px*m/s) every ``update_every`` steps.

    The translational velocity ``t`` (m/s, camera frame) comes from ground-truth poses
    (``R_wc^T dp/dt``), velocity samples (``t vx vy vz`` per line, camera frame, m/s)
    or a constant. ``per="patch"`` sends one value per ``patch_size`` square taken at
    the patch centre (the paper); ``per="pixel"`` is exact at every pixel. Intrinsics
    come from the recording's calibration unless given as ``intrinsics: [fx, fy, cx, cy]``.

    A distorted lens (the calibration's, or ``distortion_model`` with ``distortion``) is
    taken into account: each sample's ``A t`` is evaluated at its undistorted point and taken
    back onto the raw sensor by the lens's Jacobian (``tofnet.kernels.lens``), so the depth
    neurons of raw pixels measure true depth. ``distortion_model: none`` ignores the lens.
    """

    outports = (PortSpec("a_t", Payload.VELOCITY_TERM, 2, "A t per pixel, px*m/s"),)
    params = (
        Param("source", "str", "groundtruth", doc="where the velocity comes from", choices=SOURCES),
        Param("velocity", "vector3", None, unit="m/s", optional=True,
              doc="constant camera-frame velocity [tx, ty, tz] (source: constant)"),
        Param("samples", "str", None, optional=True, reads_file=True,
              doc="file of 't vx vy vz' lines, seconds and m/s in the camera frame (source: samples)"),
        Param("per", "str", "patch", doc="one A t per patch (paper) or per pixel (exact)", choices=("patch", "pixel")),
        Param("patch_size", "int", 30, unit="px", doc="side of the square patches sharing one A t",
              minimum=1, maximum=65536),
        Param("update_every", "int", 1, unit="steps", doc="steps between two A t updates",
              minimum=1, maximum=1_000_000),
        Param("intrinsics", "floats", None, unit="px", optional=True,
              doc="[fx, fy, cx, cy]; from the recording's calibration when omitted"),
        Param("distortion_model", "str", None, optional=True, choices=DISTORTION_MODELS,
              doc="lens model of 'distortion'; 'none' ignores the lens; omitted: the calibration's lens "
                  "(when the intrinsics come from it)"),
        Param("distortion", "floats", None, optional=True,
              doc="lens coefficients: radtan k1 k2 p1 p2 [k3], equidistant k1 k2 k3 k4 (OpenCV)"),
    )
    vars = (Var("last_velocity", "vector", "float64", "m/s", "camera velocity of the last update sent (NaN before the "
                "first)", channels=3),)
    placement = "host"

    def field_layout(self, port: str) -> tuple[int, int]:
        """One ``A t`` per ``patch_size`` square (per pixel: 1), every ``update_every`` steps."""
        return (int(self.patch_size) if self.per == "patch" else 1, int(self.update_every))

    def _check(self) -> None:
        values = self._values
        if values["source"] == "constant" and values["velocity"] is None:
            raise NetworkError(f"{self.name}: source 'constant' needs velocity: [tx, ty, tz] in m/s")
        if values["source"] == "samples" and values["samples"] is None:
            raise NetworkError(f"{self.name}: source 'samples' needs samples: a file of 't vx vy vz' lines")
        intrinsics = values["intrinsics"]
        if intrinsics is not None and len(intrinsics) != 4:
            raise NetworkError(f"{self.name}.intrinsics: expected [fx, fy, cx, cy] (4 numbers), got {len(intrinsics)}")
        model, coefficients = values["distortion_model"], values["distortion"]
        if coefficients is not None:
            if model in (None, "none"):
                raise NetworkError(f"{self.name}.distortion: needs distortion_model: radtan or equidistant")
            if len(coefficients) not in COEFFICIENTS[model]:
                raise NetworkError(f"{self.name}.distortion: {model} takes "
                                   f"{' or '.join(map(str, COEFFICIENTS[model]))} coefficients, got {len(coefficients)}")
        elif model in COEFFICIENTS:
            raise NetworkError(f"{self.name}.distortion_model: {model} needs distortion: its coefficients")
        if intrinsics is not None and not (intrinsics[0] > 0 and intrinsics[1] > 0):
            raise NetworkError(f"{self.name}.intrinsics: focal lengths fx, fy must be positive (pixels), "
                               f"got {intrinsics[0]:g}, {intrinsics[1]:g}")
