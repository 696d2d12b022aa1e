"""DepthProcess: depth from the time-of-travel counters and the known camera velocity."""

from __future__ import annotations

from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var
from tofnet.errors import NetworkError


class DepthProcess(Process):
    """Paper eq. 8, one neuron per pixel: ``Z = (A t)_x * td_x + (A t)_y * td_y``.

    Of two opposite directions that both fire, the smaller count is kept; equal counts
    give no measurement on that axis. ``td = ±count * timestep / distance`` seconds per
    pixel (+ for motion towards +u or +v); an axis without a spike contributes 0. ``Z``
    (metres) is emitted when an axis was measured and ``min_depth < Z < max_depth``;
    the rest are counted as rejected.
    """

    inports = (
        PortSpec("counts", Payload.COUNT, 4, "time-of-travel counters (+u, -u, +v, -v), steps"),
        PortSpec("a_t", Payload.VELOCITY_TERM, 2, "A t from the velocity process, px*m/s"),
    )
    outports = (PortSpec("depth", Payload.DEPTH, 1, "depth estimate, metres", required=False),)
    params = (
        Param("min_depth", "length", 0.05, unit="m", doc="estimates at or below are rejected", minimum=0.0),
        Param("max_depth", "length", 20.0, unit="m", doc="estimates at or above are rejected", minimum=0.0),
    )
    vars = (Var("a_t", "channels", "float64", "px*m/s", "A t each neuron holds: the last update that arrived "
                "(0 before the first)", channels=2),)
    # 4 time differences + 2 velocity terms (paper §4.2); one neuron.
    resources_per_pixel = {"accumulators": 6, "neurons": 1}

    def _check(self) -> None:
        if self._values["min_depth"] >= self._values["max_depth"]:
            raise NetworkError(f"{self.name}: min_depth ({self._values['min_depth']:g} m) must be below "
                               f"max_depth ({self._values['max_depth']:g} m)")
