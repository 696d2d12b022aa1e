"""InputProcess: events from the camera into the network, one spike per active pixel per step."""

from __future__ import annotations

from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process

#: Default refractory period, seconds. Chosen from the refractory sweep in
#: ``benchmarks/refractory_sweep.py`` on the built-in scenarios; see docs/semantics.md.
DEFAULT_REFRACTORY = "5ms"


class InputProcess(Process):
    """Bins camera events into timesteps and sends one graded spike per active pixel.

    Step ``k`` covers ``[t0 + k*timestep, t0 + (k+1)*timestep)``. An event is dropped
    (and counted) when its pixel accepted an event less than ``refractory`` seconds
    earlier, when its pixel already sent a spike in this step, or when it lies
    outside ``sensor_size``. The spike carries the event's polarity (1 = ON).
    Runs on the host (the paper's embedded x86), not on a neuromorphic core.
    """

    outports = (PortSpec("events", Payload.POLARITY, 1, "one spike per active pixel, carrying its polarity"),)
    params = (
        Param("sensor_size", "size", (240, 180), unit="px", doc="sensor (width, height)"),
        Param("timestep", "duration", "1ms", unit="s", doc="duration of one network step", minimum=1e-9),
        Param("refractory", "duration", DEFAULT_REFRACTORY, unit="s",
              doc="minimum time between two accepted events of one pixel (0 disables)", minimum=0.0),
        Param("refractory_per_polarity", "bool", False,
              doc="apply the refractory period to ON and OFF events separately"),
        Param("t0", "duration", None, unit="s", optional=True,
              doc="start of step 0; the first event's time when omitted"),
    )
    placement = "host"
