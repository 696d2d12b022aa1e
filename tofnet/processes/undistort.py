"""UndistortProcess: spikes moved from the raw sensor pixel to the undistorted image (lens correction)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tofnet.core.counters import Count
from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.errors import DataError, NetworkError

if TYPE_CHECKING:
    from tofnet.io.recording import Intrinsics

MODELS = ("radtan", "equidistant")
#: Coefficients each model takes: radtan k1 k2 p1 p2 [k3] (k3 = 0 when left out), equidistant k1 k2 k3 k4.
COEFFICIENTS = {"radtan": (4, 5), "equidistant": (4,)}


class UndistortProcess(Process):
    """Moves each spike from its raw sensor pixel to the nearest pixel of the undistorted image.

    A spike received in step ``k`` at raw pixel ``(u, v)`` is sent on in step ``k`` at
    ``(u', v')``, the undistorted image coordinates of ``(u, v)`` with the same camera
    matrix and image size (``cv::undistortPoints(..., P=K)``) rounded to the nearest pixel
    (halves up); polarity is carried. The lens is ``model`` (``radtan``: ``k1 k2 p1 p2
    [k3]`` of ``calib.txt`` and ROS ``plumb_bob``; ``equidistant``: ``k1 k2 k3 k4`` of
    OpenCV's fisheye model, DSEC, M3ED) with ``coefficients`` and the camera matrix
    ``intrinsics: [fx, fy, cx, cy]`` (px); each comes from the recording's calibration
    when left out (``model`` and ``coefficients`` together). Counted: ``passed``;
    ``left_image``, a spike whose undistorted pixel lies outside the image or which the
    model cannot invert (beyond the fold of a strong barrel); ``merged``, a spike that
    lands on an undistorted pixel another spike of the same step already took (a port
    carries one spike per pixel and step: the first in canonical order, raw ``y`` then
    ``x``, is sent). ``passed + left_image + merged`` = spikes received.

    On Loihi 2 this is connectivity, not computation: the axon of raw pixel ``p``'s input
    spike targets the synapses of the undistorted pixel's time-of-travel units instead of
    its own (a fixed, one-to-one-or-none table), so it costs no neuron, accumulator or
    core. It is declared ``placement = "host"`` with no resources, which is what the
    compiler counts (0 cores); its table is applied where the events enter the chip.
    tofnet's graph still delays each connection by one step, so the network's latency
    grows by one step (on the chip the table folds into the input's axons and adds none).

    The velocity process feeding the depth neurons behind it must then see a pinhole
    (``distortion_model: none``; ``depth_network(undistort=...)`` sets it), or the lens is
    corrected twice. The default network does not move spikes: its velocity process takes
    the lens into account on the raw pixels, which keeps every pixel and is more accurate
    (docs/formats.md, "Lens distortion").
    """

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes at raw sensor pixels, one per pixel and step at most"),)
    outports = (PortSpec("undistorted", Payload.POLARITY, 1, "the spikes at their undistorted pixels, one per "
                         "pixel and step"),)
    counters = (Count("passed", "output", "spikes sent at their undistorted pixels"),
                Count("left_image", "dropped", "undistorted outside the sensor"),
                Count("merged", "dropped", "a second spike on one undistorted pixel in a step"))
    params = (
        Param("model", "str", None, optional=True, choices=MODELS,
              doc="lens model; from the recording's calibration when null (with coefficients)"),
        Param("coefficients", "floats", None, optional=True,
              doc="radtan: k1 k2 p1 p2 [k3]; equidistant: k1 k2 k3 k4; from the recording's calibration when null"),
        Param("intrinsics", "floats", None, unit="px", optional=True,
              doc="camera matrix [fx, fy, cx, cy]; from the recording's calibration when null"),
    )
    placement = "host"

    def _check(self) -> None:
        model, coefficients, intrinsics = (self._values[k] for k in ("model", "coefficients", "intrinsics"))
        if (model is None) != (coefficients is None):
            given, missing = ("model", "coefficients") if coefficients is None else ("coefficients", "model")
            raise NetworkError(f"{self.name}.{missing}: needed with {given} (give both, or neither to take the "
                               "lens from the recording's calibration)")
        if model is not None and len(coefficients) not in COEFFICIENTS[model]:
            expected = " or ".join(map(str, COEFFICIENTS[model]))
            raise NetworkError(f"{self.name}.coefficients: the {model} model takes {expected} numbers, "
                               f"got {len(coefficients)}")
        if intrinsics is not None and len(intrinsics) != 4:
            raise NetworkError(f"{self.name}.intrinsics: expected [fx, fy, cx, cy] (4 numbers), got {len(intrinsics)}")
        if intrinsics is not None and not (intrinsics[0] > 0 and intrinsics[1] > 0):
            raise NetworkError(f"{self.name}.intrinsics: focal lengths fx, fy must be positive (pixels), "
                               f"got {intrinsics[0]:g}, {intrinsics[1]:g}")

    def lens(self, calibration: "Intrinsics | None", source: str = "the recording") -> "Intrinsics":
        """The camera matrix and distortion this process undoes: its own parameters where given, else
        ``calibration``'s (the recording's). Radtan coefficients are padded to five (k3 = 0)."""
        from tofnet.io.recording import Intrinsics

        if self.intrinsics is not None:
            fx, fy, cx, cy = self.intrinsics
        elif calibration is not None:
            fx, fy, cx, cy = calibration.fx, calibration.fy, calibration.cx, calibration.cy
        else:
            raise DataError(f"{source}: no camera calibration; the process '{self.name}' needs fx, fy, cx, cy: "
                            "add one (calib.txt) or set intrinsics: [fx, fy, cx, cy]")
        if self.model is not None:
            model, coefficients = self.model, tuple(self.coefficients)
        elif calibration is not None and calibration.distortion:
            model, coefficients = calibration.distortion_model, tuple(calibration.distortion)
        elif calibration is not None:
            model, coefficients = "radtan", ()  # the recording's lens has no distortion: nothing moves
        else:
            raise DataError(f"{source}: no lens distortion; the process '{self.name}' needs model and coefficients")
        if model == "radtan" and len(coefficients) == 4:
            coefficients += (0.0,)
        return Intrinsics(fx, fy, cx, cy, distortion=coefficients, distortion_model=model)
