"""A multiproc worker's band: the fused kernel over its rows, fed through shared memory (worker side).

The host (``tofnet.backends.shared_bands``) writes each packet's events once into a shared
buffer; every worker lists the positions of its rows' events (widened by the input reach) and
runs its ``TimeOfTravelKernel`` on them in place, as a thread's band does
(``tofnet.backends.bands``), writing its estimates and time-of-travel spikes into its part of
two shared output buffers; only small messages (counts, sizes) cross the pipe.
"""

from __future__ import annotations

import numpy as np

from tofnet.backends.band_merge import rows_read
from tofnet.backends.shared_memory import attach
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE, TOT_DTYPE


class BandWorker:
    """One band of the paper's chain in a worker process (built from the host's ``band`` message)."""

    def __init__(self, spec: dict):
        from tofnet.models.binding import UpdateRows, velocity_table
        from tofnet.kernels.kernel_config import Region
        from tofnet.kernels.region import TimeOfTravelKernel

        config = spec["config"]
        width, _ = config.sensor_size
        self.config, self.index = config, spec["index"]
        self.keep = rows_read(spec["band"], spec["reach"], config.sensor_size[1], spec["index"] == 0)
        self.kernel = TimeOfTravelKernel(config, Region(0, width, *spec["band"]), 0)
        source, step, every = spec["velocity_source"], config.timestep_us, config.update_every
        self.updates = UpdateRows(lambda first, count: velocity_table(source, self.kernel.t0_us, step, every, count,
                                                                      first), spec["lookahead"])
        self._index = np.empty(0, np.int64)  # the positions of this band's events in a packet
        self.maps: list = []
        self.remap(spec["buffers"])

    def remap(self, buffers: dict) -> None:
        """Map the host's (grown) buffers: events, estimates and spikes (``(pid, fd, bytes)`` each)."""
        self.maps = [attach(buffers[name]) for name in ("events", "depth", "tot")]
        self.capacity = buffers["capacity"]
        self.events = np.frombuffer(self.maps[0], EVENT_DTYPE, self.capacity)
        depth = np.frombuffer(self.maps[1], DEPTH_DTYPE)
        tot = np.frombuffer(self.maps[2], TOT_DTYPE)
        self.depth = depth[self.index * self.capacity:(self.index + 1) * self.capacity]
        self.tot = tot[4 * self.index * self.capacity:4 * (self.index + 1) * self.capacity]

    def run(self, n: int, t0_us: int, record_tot: bool) -> tuple[int, int]:
        """Run this band's events of the packet's ``n``; ``(estimates, spikes)`` written, ``(-1, 0)`` when
        the packet is out of time order (refused by every band: nothing changed)."""
        from tofnet.errors import BackendError
        from tofnet.kernels.bands import select_rows
        from tofnet.kernels.region import UNSORTED

        if self.kernel.t0_us != t0_us:
            self.kernel.t0_us = t0_us
            self.updates.clear()
        if len(self._index) <= n:
            self._index = np.empty(max(n + 1, 2 * len(self._index)), np.int64)
        events = self.events[:n]
        m = select_rows(events, self.keep, self._index)
        if m < 0:
            return -1, 0
        try:
            end, n_tot = self.kernel.run_events(events, self.updates.rows, self.depth, 0, record_tot, None, True,
                                                self._index[:m])
        except BackendError as error:
            if str(error) == UNSORTED:
                return -1, 0
            raise
        if record_tot and n_tot:
            self.tot[:n_tot] = self.kernel.buffers()[2][:n_tot]
        return end, n_tot

    def counts(self) -> tuple:
        k = self.kernel
        return k.accepted, [int(c) for c in k.drops], k.tot_spikes, [int(c) for c in k.outcomes]

    def handle(self, message: tuple) -> tuple:
        kind = message[0]
        if kind == "band_run":  # the counts ride along: the host reads them after every packet
            return ("band_run", *self.run(*message[1:]), self.counts())
        if kind == "band_promise":
            self.kernel.promise(message[1])
            return ("band_promise",)
        if kind == "band_counts":
            return ("band_counts", self.counts())
        if kind == "band_map":
            self.remap(message[1])
            return ("band_map",)
        raise ValueError(f"unknown band message {kind!r}")
