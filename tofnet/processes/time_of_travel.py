"""TimeOfTravelProcess: four counters per pixel measuring how long an edge took to arrive."""

from __future__ import annotations

from tofnet.core.counters import Count
from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var


class TimeOfTravelProcess(Process):
    """Paper Algorithm 1: four units per pixel, one per direction (+u, -u, +v, -v).

    Unit (p, D) is triggered by pixel p and facilitated by pixel ``p - distance*D``.
    Each step, in order: (1) a trigger with the stored polarity and ``counter > 0``
    sends ``counter`` (steps) and resets it; (2) a running counter increments, and
    resets to 0 past ``2**counter_bits - 1`` (overflow); (3) a facilitating spike sets
    ``counter = 1`` and stores its polarity. Facilitation in step a and a trigger in
    step b > a send ``b - a``.
    """

    inports = (PortSpec("events", Payload.POLARITY, 1, "input spikes: trigger and facilitating"),)
    outports = (PortSpec("counts", Payload.COUNT, 4, "counter values per direction (+u, -u, +v, -v), steps"),)
    counters = (Count("spikes", "output", "counter spikes sent", total="tot_spikes"),)
    params = (
        Param("distance", "int", 1, unit="px", doc="pixels between facilitating and trigger pixel",
              minimum=1, maximum=255),
        Param("counter_bits", "int", 8, unit="bits", doc="width of the unsigned counter", minimum=1, maximum=30),
    )
    vars = (Var("counter", "channels", "int64", "steps", "the counter each unit shows at the start of the step "
                "(0: idle), channels +u, -u, +v, -v", channels=4, settable=True, low=0,
                high=(1 << 30) - 1),
            Var("polarity", "channels", "uint8", "", "the polarity of the unit's last facilitation (0 when idle)",
                channels=4, settable=True, low=0, high=1))
    # 4 units x (trigger + facilitating) accumulators; 4 neurons (paper §4.1).
    resources_per_pixel = {"accumulators": 8, "neurons": 4}

    def receptive_offsets(self) -> list[tuple[int, int]]:
        """The trigger pixel and the four facilitating pixels ``distance`` away along ±u, ±v."""
        d = self.distance
        return [(0, 0), (d, 0), (-d, 0), (0, d), (0, -d)]
