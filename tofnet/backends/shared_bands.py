"""The multiproc backend's fast path: each worker process runs its share of the cores as one band.

For the paper's chain, a worker holds the rows of the compiled cores it was dealt
(``band_rows``) as one fused kernel (``_band_worker``). Per packet the host writes the events
once into shared memory (``shared_memory``: memfds, never in ``/dev/shm``) and sends each
worker a few numbers; the workers run their bands, wait for each other, and each merges its
share of the steps into the result in shared memory, in the canonical order — the same bytes as
``fixed`` (docs/backends.md, "The multiproc backend"). A ``run`` collects its estimates in
buffers the workers write (``allocate``); other callers' arrays are copied into from a shared
buffer. ``SharedBandKernel`` offers ``TimeOfTravelKernel``'s streaming API, so ``FusedStream`` runs it.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from tofnet.backends.band_merge import BandsBase
from tofnet.backends.shared_memory import Rendezvous, SharedBuffer
from tofnet.compiler.bands import Band
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE, TOT_DTYPE
from tofnet.kernels.kernel_config import KernelConfig, Region
from tofnet.kernels.region import UNSORTED, TimeOfTravelKernel


def band_rows(compiled, layer: str, plans) -> list[Band]:
    """Rows of each worker's share of ``layer``'s cores (``plan_workers`` deals them out in patch
    order): the worker's band starts at its first core's row; the first starts at 0, the last ends at
    the sensor's last row. Workers whose shares start on the same row are merged into one band."""
    height = compiled.network.process(layer).sensor_size[1]
    cores = compiled.cores_of(layer)  # once: 1280x720 has ~1000 cores per layer
    starts = []
    for plan in plans:
        dealt = set(plan.cores)
        rows = [core.y0 for core in cores if core.index in dealt]
        if rows:
            starts.append(min(rows))
    starts = sorted(set([0] + starts[1:]))
    return [(a, b) for a, b in zip(starts, starts[1:] + [height]) if a < b]


def split_facts(compiled, plans) -> dict:
    """How a model-by-model run was split over the workers, for the summary (``RunResult.extra``): each
    worker's rows (of the first core-placed layer's cores), and the processes the host runs whole."""
    network = compiled.network
    layers = [layer.name for layer in compiled.layers]
    rows = band_rows(compiled, layers[0], plans) if layers else [(0, network.sensor_size[1])]
    return {"workers": len(plans), "bands": [list(band) for band in rows],
            "whole": [p.name for p in network.processes if p.placement != "core"], "unit": "processes"}


class SharedBandKernel(BandsBase):
    """The fused kernel over worker processes, one band each; ``exchange({worker: message}, stuck, meanwhile)``
    talks to them (``MultiprocSession._exchange``)."""

    def __init__(self, config: KernelConfig, bands: Sequence[Band], reach: int, velocity_source,
                 exchange: Callable[..., dict[int, tuple]], t0_us: int = 0, lookahead: int = 1024):
        super().__init__(config, t0_us)
        self.bands = list(bands)
        self._exchange = exchange
        self._buffers: list[SharedBuffer] = []
        self._events = self._depth = self._spikes = self._merged = self._arrived = None
        self.capacity = 0
        self._counts: list[tuple] | None = None  # the workers' counts after the latest packet
        #: The latest buffer ``allocate`` made (the workers merge into it), its array, and how many were made.
        self._result: tuple[SharedBuffer, np.ndarray] | None = None
        self._results = 0
        self._packets = 0  # packets run (the workers write the latest they ran into ``_arrived``)
        self._ahead: np.ndarray | None = None  # the next packet (``next_packet``)
        self._staged: tuple | None = None  # ``(address, events, where)`` of a packet copied ahead
        self._map(1 << 12)
        try:
            self._open(self._addresses(), reach, velocity_source, lookahead)
        except BaseException:
            self.close()
            raise
        self.facts = {"workers": len(self.bands), "bands": [list(b) for b in self.bands], "shared_memory": True,
                      "unit": "processes"}

    def _open(self, addresses: dict, reach: int, velocity_source, lookahead: int) -> None:
        """Give each worker its band (``_band_worker.BandWorker``) and its ends of the pipes by which the
        workers wait for each other (closed here once each has opened its own)."""
        rendezvous = Rendezvous(len(self.bands)) if len(self.bands) > 1 else None
        try:
            self._exchange({w: ("band", {"config": self.config, "index": w, "band": band, "lookahead": lookahead,
                                         "reach": reach, "velocity_source": velocity_source, "buffers": addresses,
                                         "gate": rendezvous and rendezvous.address(w)})
                            for w, band in enumerate(self.bands)})
        finally:
            if rendezvous is not None:
                rendezvous.close()

    # -- shared buffers ------------------------------------------------------------------------
    def _map(self, capacity: int) -> None:
        """Buffers for packets of up to ``capacity`` events (the old ones are released)."""
        self._release_buffers()
        n = len(self.bands)
        self._staged = None  # the buffers' contents go
        self._buffers = [SharedBuffer(2 * capacity * EVENT_DTYPE.itemsize, "tofnet-events"),
                         SharedBuffer(n * capacity * DEPTH_DTYPE.itemsize, "tofnet-depth"),
                         SharedBuffer(4 * n * capacity * TOT_DTYPE.itemsize, "tofnet-tot"),
                         SharedBuffer(capacity * DEPTH_DTYPE.itemsize, "tofnet-merged"),
                         SharedBuffer(n * 8, "tofnet-gate")]
        self.capacity = capacity
        self._events = self._buffers[0].array(EVENT_DTYPE, 2 * capacity)  # two packets: one runs, one is copied
        self._depth = self._buffers[1].array(DEPTH_DTYPE, n * capacity)
        self._spikes = self._buffers[2].array(TOT_DTYPE, 4 * n * capacity)
        self._merged = self._buffers[3].array(DEPTH_DTYPE, capacity)
        self._arrived = self._buffers[4].array(np.int64, n)  # per worker, the latest packet it ran and waits on

    def _addresses(self) -> dict:
        events, depth, tot, merged, gate = (b.address for b in self._buffers)
        return {"events": events, "depth": depth, "tot": tot, "merged": merged, "gate": gate,
                "capacity": self.capacity}

    def allocate(self, count: int, dtype) -> np.ndarray:
        """An array of ``count`` records for a run's estimates, in memory the workers map: they merge
        into it in place (no copy, and its fresh pages first touched by the workers, each its share).
        It stays valid after ``close`` (its memory goes with the last array on it); other records:
        ``np.empty``."""
        if np.dtype(dtype) != DEPTH_DTYPE:
            return np.empty(count, dtype)
        self._let_go_result()
        buffer = SharedBuffer(max(count, 1) * DEPTH_DTYPE.itemsize, "tofnet-result")
        self._results += 1
        self._result = (buffer, buffer.array(DEPTH_DTYPE, count))
        return self._result[1]

    def _let_go_result(self) -> None:
        """Close the latest result buffer's file (its mapping stays while an array uses it)."""
        if self._result is not None:
            self._result[0].close()
            self._result = None

    def _release_buffers(self) -> None:
        """Release the packets' buffers: the views first, so that each map can close."""
        self._events = self._depth = self._spikes = self._merged = self._arrived = None
        for buffer in self._buffers:
            buffer.close()
        self._buffers = []

    def close(self) -> None:
        """Release the shared buffers and the result's file (idempotent)."""
        self._release_buffers()
        self._let_go_result()

    # -- what FusedStream reads ----------------------------------------------------------------
    def _band_counts(self) -> list[tuple]:
        if self._counts is None:  # before the first packet (each packet's replies bring them: no round trip)
            replies = self._exchange({w: ("band_counts",) for w in range(len(self.bands))})
            self._counts = [replies[w][1] for w in range(len(self.bands))]
        return self._counts

    def promise(self, until_us: int) -> None:
        self._t_hi = max(self._t_hi, int(until_us))
        self._exchange({w: ("band_promise", int(until_us)) for w in range(len(self.bands))})

    def join_packets(self, depth: np.ndarray, seams: list[int]) -> np.ndarray:
        if not hasattr(self, "_join_kernel"):  # a 1-row kernel: its sort is all join_packets uses
            self._join_kernel = TimeOfTravelKernel(self.config, Region(0, self.config.sensor_size[0], 0, 1))
        return self._join_kernel.join_packets(depth, seams)

    # -- running -------------------------------------------------------------------------------
    def _target(self, into: np.ndarray, offset: int) -> tuple | None:
        """Where the workers merge a packet's estimates: ``(result id, its address, offset)`` when ``into``
        is the latest ``allocate``'s array, else None (their shared buffer, then copied into ``into``)."""
        result = self._result
        if result is None or into.ctypes.data != result[1].ctypes.data or len(into) != len(result[1]):
            return None
        return self._results, result[0].address, offset

    def next_packet(self, events: np.ndarray) -> None:
        """The packet the next ``run_events`` will be given, unchanged (a caller that knows, as ``run``
        does): it is copied into shared memory while this one runs, off the host's serial part."""
        self._ahead = events if len(events) and events.flags.c_contiguous else None

    def _copy(self, events: np.ndarray, at: int) -> None:
        raw = np.dtype((np.void, EVENT_DTYPE.itemsize))
        self._events[at:at + len(events)].view(raw)[:] = np.ascontiguousarray(events).view(raw)

    def run_events(self, events: np.ndarray, velocity, into: np.ndarray | None = None, offset: int = 0,
                   record_tot: bool = False, span=None, canonical: bool = True) -> tuple[int, int]:
        """As ``TimeOfTravelKernel.run_events`` (``velocity`` unused: each worker computes its rows);
        the estimates are always in the canonical order."""
        into, offset = self._output(events, into, offset)
        n = len(events)
        if n == 0:
            return offset, 0
        workers = range(len(self.bands))
        if n > self.capacity:
            self._map(max(n, 2 * self.capacity))
            self._exchange({w: ("band_map", self._addresses()) for w in workers})
        staged, self._staged = self._staged, None
        ahead, self._ahead = self._ahead, None
        if staged is not None and staged[:2] == (events.ctypes.data, n) and events.flags.c_contiguous:
            first = staged[2]  # copied while the previous packet ran
        else:
            first = 0
            self._copy(events, first)

        def meanwhile() -> None:  # while the workers run this packet, the next one goes to the other half
            if ahead is not None and len(ahead) <= self.capacity:
                self._copy(ahead, self.capacity - first)
                self._staged = (ahead.ctypes.data, len(ahead), self.capacity - first)

        target = self._target(into, offset)
        try:
            self._packets += 1
            replies = self._exchange({w: ("band_run", first, n, self._t0, bool(record_tot), target, self._packets)
                                      for w in workers}, lambda: np.flatnonzero(self._arrived != self._packets),
                                     meanwhile)
        except BaseException:
            self._broken = True
            self._staged = None
            raise
        self._counts = [replies[w][4] for w in workers]
        refused = sum(replies[w][1] < 0 for w in workers)
        if refused:  # every band checks the packet's time order: all refuse it, or something is wrong
            self._broken = refused < len(self.bands)
            raise BackendError(UNSORTED)
        self._t_hi = max(self._t_hi, int(events["t"][-1]))
        end = max(replies[w][3] for w in workers)  # each worker merged its share of the steps
        if target is None:  # into the caller's array
            raw = np.dtype((np.void, DEPTH_DTYPE.itemsize))
            into[offset:offset + end].view(raw)[:] = self._merged[:end].view(raw)
            end += offset
        if not record_tot:
            return end, 0
        cap = self.capacity
        return end, self._merged_tot(self._spikes, [(4 * w * cap, 4 * w * cap + replies[w][2]) for w in workers])
