"""InputProcess: events from the camera into the network, one spike per active pixel per step."""

from __future__ import annotations

from tofnet.core.counters import Count, reader_counts
from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var
from tofnet.units import MAX_PERIOD_S

#: Default refractory period. An edge makes each pixel it crosses fire a burst of
#: events (a 1-2 px edge takes 1-2 pixel crossings to pass); a refractory period
#: shorter than the time the image takes to move about one pixel lets the units pair
#: events inside bursts, so times come out short and depths too near; a longer one
#: drops the next edge (coverage, over-estimates). 60 ms had the lowest average of
#: mean and median relative error over the eight built-in scenarios with realistic
#: pixels (``benchmarks/refractory_sweep.py``; 50-75 ms are within 2 points), and is
#: the pixel-crossing time at the paper's depths (~6 m at 0.55 m/s). Near or fast
#: scenes want less (fast_slider: 5-10 ms). See docs/accuracy.md.
DEFAULT_REFRACTORY = "60ms"



class InputProcess(Process):
    """Bins camera events into timesteps and sends one graded spike per active pixel.

    Step ``k`` covers ``[t0 + k*timestep, t0 + (k+1)*timestep)``. An event is dropped
    (and counted) when its pixel accepted an event less than ``refractory`` seconds
    earlier, when its pixel already sent a spike in this step, or when it lies
    outside ``sensor_size``. The spike carries the event's polarity (1 = ON).
    Runs on the host (the paper's embedded x86), not on a neuromorphic core.
    """

    outports = (PortSpec("events", Payload.POLARITY, 1, "one spike per active pixel, carrying its polarity"),)
    counters = (*reader_counts("events sent on as spikes"),
                Count("refractory", "dropped", "within the refractory period of the pixel's last accepted event"),
                Count("same_step", "dropped", "the pixel already sent a spike in this step"))
    params = (
        Param("sensor_size", "size", (240, 180), unit="px", doc="sensor (width, height)"),
        Param("timestep", "duration", "1ms", unit="s", doc="duration of one network step",
              minimum=1e-6, maximum=MAX_PERIOD_S),
        Param("refractory", "duration", DEFAULT_REFRACTORY, unit="s",
              doc="minimum time between two accepted events of one pixel (0 disables)", minimum=0.0,
              maximum=MAX_PERIOD_S),
        Param("refractory_per_polarity", "bool", False,
              doc="apply the refractory period to ON and OFF events separately"),
        Param("t0", "duration", None, unit="s", optional=True,
              doc="start of step 0; the first event's time when omitted"),
    )
    vars = (Var("last_accepted", "pixel", "int64", "µs", "time of the pixel's last accepted event (any polarity); "
                "-2**62 before the first", settable=True, low=-(1 << 62), high=(1 << 61) - 1),)
    placement = "host"
