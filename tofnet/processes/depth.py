"""DepthProcess: depth from the time-of-travel counters and the known camera velocity."""

from __future__ import annotations

from tofnet.core.counters import Count
from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var
from tofnet.errors import NetworkError


class DepthProcess(Process):
    """Paper eq. 8, one neuron per pixel: ``Z = (A t)_x * td_x + (A t)_y * td_y``; eq. 7 with ``b_w``.

    Of two opposite directions that both fire, the smaller count is kept; equal counts
    give no measurement on that axis. ``td = ±count * timestep / distance`` seconds per
    pixel (+ for motion towards +u or +v); an axis without a spike contributes 0. ``Z``
    (metres) is emitted when an axis was measured and ``min_depth < Z < max_depth``;
    the rest are counted as rejected.

    With ``b_w`` connected (an ``AngularVelocityProcess``), the camera's rotation is
    compensated (paper eq. 7): ``r = 1 − (B ω)·td`` is the share of the measured image
    motion that translation explains; ``r <= min_share`` is rejected as
    ``rotation_dominated``, else ``Z = ((A t)·td) / r`` (docs/semantics.md). The default
    0.1 rejects the gross failures (depths several times too large where ``r`` is near 0)
    at the cost of 0–10 % of the estimates on the simulated rotating scenes (docs/rotation.md).
    """

    inports = (
        PortSpec("counts", Payload.COUNT, 4, "time-of-travel counters (+u, -u, +v, -v), steps"),
        PortSpec("a_t", Payload.VELOCITY_TERM, 2, "A t from the velocity process, px*m/s"),
        PortSpec("b_w", Payload.ROTATION_TERM, 2, "B ω from an angular velocity process, px/s: eq. 7 when "
                 "connected, eq. 8 when not", required=False),
    )
    outports = (PortSpec("depth", Payload.DEPTH, 1, "depth estimate, metres"),)
    counters = (Count("no_measurement", "rejected", "no signed count on either axis"),
                Count("too_near", "rejected", "below min_depth"),
                Count("too_far", "rejected", "beyond max_depth"),
                Count("rotation_dominated", "rejected", "eq. 7's translational share at or below min_share (only "
                      "with an angular velocity input)"),
                Count("emitted", "output", "estimates sent"))
    params = (
        Param("min_depth", "length", 0.05, unit="m", doc="estimates at or below are rejected", minimum=0.0),
        Param("max_depth", "length", 20.0, unit="m", doc="estimates at or above are rejected", minimum=0.0),
        Param("min_share", "float", 0.1, doc="with b_w: estimates whose translational share r = 1 - (B ω)·td is "
              "at or below are rejected (rotation_dominated)", minimum=0.0),
    )
    vars = (Var("a_t", "channels", "float64", "px*m/s", "A t each neuron holds: the last update that arrived "
                "(0 before the first)", channels=2),
            Var("b_w", "channels", "float64", "px/s", "B ω each neuron holds: the last rotation update that arrived "
                "(0 before the first, and without rotation)", channels=2))
    @property
    def resources_per_pixel(self) -> dict[str, int]:  # type: ignore[override]
        """4 time differences + 2 velocity terms (paper §4.2), + 2 rotation terms with ``b_w``; one neuron."""
        return {"accumulators": 8 if self.rotating else 6, "neurons": 1}

    @property
    def rotating(self) -> bool:
        """True when ``b_w`` is connected: the neurons compute eq. 7."""
        return bool(self.ports["b_w"].sources)

    def compiler_notes(self) -> tuple[str, ...]:
        if not self.rotating:
            return ()
        return ("eq. 7 (rotation compensated): one division per estimate, Z = (A t)·td / r, which the paper's "
                "Loihi 2 mapping (eq. 8: multiply-adds only) avoided; 2 more accumulators per pixel for B ω",)

    def _check(self) -> None:
        if self._values["min_depth"] >= self._values["max_depth"]:
            raise NetworkError(f"{self.name}: min_depth ({self._values['min_depth']:g} m) must be below "
                               f"max_depth ({self._values['max_depth']:g} m)")
        if self._values["min_share"] >= 1.0:
            raise NetworkError(f"{self.name}.min_share: expected a share below 1 (0.1 rejects the gross failures "
                               f"of eq. 7), got {self._values['min_share']:g}")
