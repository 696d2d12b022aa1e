"""BackgroundActivityFilterProcess: the standard event-camera denoiser, as a layer of the graph."""

from __future__ import annotations

from tofnet.core.counters import Count
from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var
from tofnet.units import MAX_PERIOD_S


class BackgroundActivityFilterProcess(Process):
    """Passes a spike only when a neighbour within ``radius`` px spiked recently.

    The background-activity filter of event cameras (Delbruck 2008; jAER, v2e): noise
    events are isolated in space and time, edges are not. A spike received in step ``k``
    at pixel ``p`` is sent on in step ``k`` when another pixel at Chebyshev distance
    ``1..radius`` from ``p`` received one in steps ``k - w .. k`` (the same step
    included, so the order of spikes within a step does not matter), ``w`` being
    ``window`` in whole steps (rounded); otherwise it is dropped and counted as
    ``isolated``. Polarity is carried through and not compared.

    On a neuromorphic core each pixel is a support compartment, which sums its
    neighbours' spikes and decays over ``window``, and a gate neuron, which passes the
    pixel's own spike while the support is up: 2 neurons and 2 accumulators per pixel.
    """

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes to filter, one per pixel and step at most"),)
    outports = (PortSpec("passed", Payload.POLARITY, 1, "the spikes a neighbour supports"),)
    counters = (Count("passed", "output", "spikes a neighbour supports"),
                Count("isolated", "dropped", "no neighbour spiked within the window"))
    params = (
        Param("radius", "int", 1, unit="px", doc="neighbourhood (Chebyshev distance) that supports a spike",
              minimum=1, maximum=16),
        Param("window", "duration", "30ms", unit="s", doc="how recent a neighbour's spike must be (jAER's default)",
              minimum=0.0, maximum=MAX_PERIOD_S),
    )
    vars = (Var("last_spike", "pixel", "int64", "steps", "the step the pixel last received a spike; -2**62 before "
                "the first", settable=True, low=-(1 << 62), high=(1 << 62) - 1),)
    resources_per_pixel = {"accumulators": 2, "neurons": 2}

    def receptive_offsets(self) -> list[tuple[int, int]]:
        """Every pixel within ``radius`` (its own included: the spike it gates)."""
        r = int(self.radius)
        return [(du, dv) for dv in range(-r, r + 1) for du in range(-r, r + 1)]
