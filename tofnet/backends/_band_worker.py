"""A multiproc worker's band: the fused kernel over its rows, fed through shared memory (worker side).

The host (``tofnet.backends.shared_bands``) writes each packet's events once into a shared
buffer; every worker lists the positions of its rows' events (widened by the input reach) and
runs its ``TimeOfTravelKernel`` on them in place, as a thread's band does
(``tofnet.backends.bands``), writing its estimates into its part of a shared buffer; then the
workers wait for each other (``shared_memory.Gate``: they tell each other how many estimates
they wrote) and each merges its share of the steps into the shared result (``merge_share``),
as the threads do. Only small messages (counts, sizes) cross the pipe to the host.
"""

from __future__ import annotations

import numpy as np

from tofnet.backends.band_merge import merge_share, rows_read
from tofnet.backends.shared_memory import Gate, attach
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
        self._result: tuple = (None, None)  # the id of the result buffer mapped, and its records
        self.gate = Gate(spec["gate"], self.index) if spec["gate"] is not None else None
        self.remap(spec["buffers"])

    def remap(self, buffers: dict) -> None:
        """Map the host's (grown) buffers: events, estimates, spikes and the merged estimates of a
        packet (``(pid, fd, bytes)`` each)."""
        self.maps = [attach(buffers[name]) for name in ("events", "depth", "tot", "merged", "gate")]
        self.capacity = buffers["capacity"]
        self.events = np.frombuffer(self.maps[0], EVENT_DTYPE, 2 * self.capacity)  # two packets' room
        self.parts = np.frombuffer(self.maps[1], DEPTH_DTYPE)  # every band's estimates, ``capacity`` apart
        tot = np.frombuffer(self.maps[2], TOT_DTYPE)
        self.merged = np.frombuffer(self.maps[3], DEPTH_DTYPE)
        self.arrived = np.frombuffer(self.maps[4], np.int64)  # per worker, the latest packet it ran
        self.depth = self.parts[self.index * self.capacity:(self.index + 1) * self.capacity]
        self.tot = tot[4 * self.index * self.capacity:4 * (self.index + 1) * self.capacity]

    def _target(self, target) -> tuple[np.ndarray, int]:
        """Where the merged estimates go: ``(result id, address, offset)`` in a result buffer of the host's
        (mapped once; an earlier one is let go), or None: the packet's merged buffer."""
        if target is None:
            return self.merged, 0
        ident, address, offset = target
        if self._result[0] != ident:
            self._result = (None, None)  # the earlier result's mapping goes before the next is made
            self._result = (ident, np.frombuffer(attach(address), DEPTH_DTYPE))
        return self._result[1], offset

    def run(self, first: int, n: int, t0_us: int, record_tot: bool, target, packet: int) -> tuple[int, int, int]:
        """Run this band's events of the packet's ``n`` (from ``first`` in the events buffer), then (every
        band run) merge this worker's share of the bands' estimates into ``target`` (``_target``;
        ``packet``: the host's count of packets, written to ``arrived`` on the way). Returns
        ``(estimates, spikes, end of the share)``: estimates -1 when the packet is out of time order
        (refused by every band: nothing changed), end -1 when nothing was merged."""
        from tofnet.errors import BackendError
        from tofnet.kernels.bands import select_rows
        from tofnet.kernels.region import UNSORTED

        if self.kernel.t0_us != t0_us:
            self.kernel.t0_us = t0_us
            self.updates.clear()
        if len(self._index) <= n:
            self._index = np.empty(max(n + 1, 2 * len(self._index)), np.int64)
        events = self.events[first:first + n]
        end, n_tot, failure = -1, 0, None
        try:
            m = select_rows(events, self.keep, self._index)
            if m >= 0:
                end, n_tot = self.kernel.run_events(events, self.updates.rows, self.depth, 0, record_tot, None,
                                                    True, self._index[:m])
        except BackendError as error:
            if str(error) != UNSORTED:
                failure = error
        except BaseException as error:  # noqa: B036 - re-raised once the other workers know
            failure = error
        # every worker reaches the gate, so that none waits for ever: -2 says this band failed; the host
        # names a worker that never got here (``packet`` not written) when none answers in time
        self.arrived[self.index] = packet
        ends = [end if failure is None else -2] if self.gate is None else \
            self.gate.gather(end if failure is None else -2)
        if failure is not None:
            raise failure
        if min(ends) < 0:  # refused (by every band: each checks the whole packet), or another band failed
            return end, 0, -1
        if record_tot and n_tot:
            self.tot[:n_tot] = self.kernel.buffers()[2][:n_tot]
        into, offset = self._target(target)
        parts = [(b * self.capacity, b * self.capacity + e) for b, e in enumerate(ends)]
        return end, n_tot, merge_share(self.parts, parts, into, offset, self.index, len(ends))

    def counts(self) -> tuple:
        k = self.kernel
        return k.accepted, [int(c) for c in k.drops], k.tot_spikes, [int(c) for c in k.outcomes]

    def handle(self, message: tuple) -> tuple:
        kind = message[0]
        if kind == "band_run":  # ``(estimates, spikes, end of the share)``; the counts ride along
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

    def close(self) -> None:
        """Let go of the gate's pipes (the mappings go with this object)."""
        if self.gate is not None:
            self.gate.close()
            self.gate = None
