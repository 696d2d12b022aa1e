"""The multiproc backend's fast path: each worker process runs its share of the cores as one band.

For the paper's chain, a worker holds the rows of the compiled cores it was dealt
(``band_rows``) as one fused kernel (``_band_worker``). Per packet the host writes the events
once into shared memory (``shared_memory``: memfds, never in ``/dev/shm``), sends each worker a
few numbers, and merges the estimates the workers wrote into shared memory in the canonical
order — the same bytes as ``fixed`` (docs/backends.md, "The multiproc backend").
``SharedBandKernel`` offers ``TimeOfTravelKernel``'s streaming API, so ``FusedStream`` runs it.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from tofnet.backends.base import REJECT_REASONS
from tofnet.backends.shared_memory import SharedBuffer
from tofnet.compiler.bands import Band, halo_rows
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE, TOT_DTYPE
from tofnet.kernels.bands import merge_by_step
from tofnet.kernels.input_filter import ACCEPTED, NEVER, first_out_of_order
from tofnet.kernels.kernel_config import KernelConfig, KernelOutput, Region
from tofnet.kernels.region import TimeOfTravelKernel


def band_rows(compiled, layer: str, plans) -> list[Band]:
    """Rows of each worker's share of ``layer``'s cores (``plan_workers`` deals them out in patch
    order): the worker's band starts at its first core's row; the first starts at 0, the last ends at
    the sensor's last row. Workers whose shares start on the same row are merged into one band."""
    height = compiled.network.process(layer).sensor_size[1]
    starts = []
    for plan in plans:
        rows = [core.y0 for core in compiled.cores_of(layer) if core.index in plan.cores]
        if rows:
            starts.append(min(rows))
    starts = sorted(set([0] + starts[1:]))
    return [(a, b) for a, b in zip(starts, starts[1:] + [height]) if a < b]


class SharedBandKernel:
    """The fused kernel over worker processes, one band each; ``exchange({worker: message})`` talks to them."""

    def __init__(self, config: KernelConfig, bands: Sequence[Band], reach: int, velocity_source,
                 exchange: Callable[[dict[int, tuple]], dict[int, tuple]], t0_us: int = 0, lookahead: int = 1024):
        self.config, self.bands = config, list(bands)
        self._exchange = exchange
        self._t0 = int(t0_us)
        self._t_hi = NEVER
        self._buffers: list[SharedBuffer] = []
        self._events = self._depth = self._spikes = None
        self.capacity = 0
        self._tot = np.empty(0, TOT_DTYPE)
        self._out = np.empty(0, DEPTH_DTYPE)
        self._broken = False
        self._map(1 << 12)
        addresses = self._addresses()
        try:
            self._open(addresses, reach, velocity_source, lookahead)
        except BaseException:
            self.close()
            raise
        self.facts = {"workers": len(self.bands), "bands": [list(b) for b in self.bands], "shared_memory": True}

    def _open(self, addresses: dict, reach: int, velocity_source, lookahead: int) -> None:
        """Give each worker its band (``_band_worker.BandWorker``)."""
        height = self.config.sensor_size[1]
        config = self.config
        self._exchange({w: ("band", {"config": config, "index": w, "band": band, "lookahead": lookahead,
                                     "rows": halo_rows(band, reach, height), "velocity_source": velocity_source,
                                     "buffers": addresses}) for w, band in enumerate(self.bands)})

    # -- shared buffers ------------------------------------------------------------------------
    def _map(self, capacity: int) -> None:
        """Buffers for packets of up to ``capacity`` events (the old ones are released)."""
        self.close()
        n = len(self.bands)
        self._buffers = [SharedBuffer(capacity * EVENT_DTYPE.itemsize, "tofnet-events"),
                         SharedBuffer(n * capacity * DEPTH_DTYPE.itemsize, "tofnet-depth"),
                         SharedBuffer(4 * n * capacity * TOT_DTYPE.itemsize, "tofnet-tot")]
        self.capacity = capacity
        self._events = self._buffers[0].array(EVENT_DTYPE, capacity)
        self._depth = self._buffers[1].array(DEPTH_DTYPE, n * capacity)
        self._spikes = self._buffers[2].array(TOT_DTYPE, 4 * n * capacity)

    def _addresses(self) -> dict:
        events, depth, tot = (b.address for b in self._buffers)
        return {"events": events, "depth": depth, "tot": tot, "capacity": self.capacity}

    def close(self) -> None:
        """Release the shared buffers (idempotent): the views first, so that each map can close."""
        self._events = self._depth = self._spikes = None
        for buffer in self._buffers:
            buffer.close()
        self._buffers = []

    # -- what FusedStream reads ----------------------------------------------------------------
    @property
    def t0_us(self) -> int:
        return self._t0

    @t0_us.setter
    def t0_us(self, value: int) -> None:
        self._t0 = int(value)

    def _counts(self) -> list[tuple]:
        replies = self._exchange({w: ("band_counts",) for w in range(len(self.bands))})
        return [replies[w][1] for w in range(len(self.bands))]

    @property
    def accepted(self) -> int:
        return sum(c[0] for c in self._counts())

    @property
    def drops(self) -> np.ndarray:
        return np.sum([c[1] for c in self._counts()], axis=0) if self.bands else np.zeros(ACCEPTED, np.int64)

    @property
    def tot_spikes(self) -> int:
        return sum(c[2] for c in self._counts())

    @property
    def outcomes(self) -> np.ndarray:
        counts = self._counts()
        return np.sum([c[3] for c in counts], axis=0) if counts else np.zeros(len(REJECT_REASONS) + 1, np.int64)

    def buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._out, np.empty(0, np.int64), self._tot

    def promise(self, until_us: int) -> None:
        self._t_hi = max(self._t_hi, int(until_us))
        self._exchange({w: ("band_promise", int(until_us)) for w in range(len(self.bands))})

    def join_packets(self, depth: np.ndarray, seams: list[int]) -> np.ndarray:
        return self._joiner().join_packets(depth, seams)

    def _joiner(self) -> TimeOfTravelKernel:
        if not hasattr(self, "_join_kernel"):  # a 1-row kernel: its sort is all join_packets uses
            self._join_kernel = TimeOfTravelKernel(self.config, Region(0, self.config.sensor_size[0], 0, 1))
        return self._join_kernel

    # -- running -------------------------------------------------------------------------------
    def process_events(self, events: np.ndarray, velocity, *, record_tot: bool = False, copy: bool = True,
                       into: np.ndarray | None = None, offset: int = 0) -> KernelOutput:
        end, n_tot = self.run_events(events, velocity, into, offset, record_tot)
        depth = self._out[:end] if into is None else into[offset:end]
        tot = self._tot[:n_tot] if record_tot else None
        if copy:
            depth, tot = depth.copy(), (tot.copy() if tot is not None else None)
        return KernelOutput(depth, np.empty(0, np.int64), tot, 0)

    def run_events(self, events: np.ndarray, velocity, into: np.ndarray | None = None, offset: int = 0,
                   record_tot: bool = False, span=None, canonical: bool = True) -> tuple[int, int]:
        """As ``TimeOfTravelKernel.run_events`` (``velocity`` unused: each worker computes its rows);
        the estimates are always in the canonical order."""
        if self._broken:
            raise BackendError("kernel state is invalid after an earlier error; start a new one")
        n = len(events)
        if into is None:
            if len(self._out) < n:
                self._out = np.empty(max(n, 2 * len(self._out)), DEPTH_DTYPE)
            into, offset = self._out, 0
        elif len(into) < offset + n:
            raise BackendError(f"output buffer holds {len(into)} estimates, {offset + n} may be written")
        if n == 0:
            return offset, 0
        if first_out_of_order(events["t"], self._t_hi) >= 0:  # refused before any worker changes
            raise BackendError("events are not sorted by time (input spikes: by step): each packet must be in "
                               "time order and follow the previous one; it was refused and the state is unchanged")
        workers = range(len(self.bands))
        if n > self.capacity:
            self._map(max(n, 2 * self.capacity))
            self._exchange({w: ("band_map", self._addresses()) for w in workers})
        raw = np.dtype((np.void, EVENT_DTYPE.itemsize))
        self._events[:n].view(raw)[:] = events.view(raw) if events.flags.c_contiguous else \
            np.ascontiguousarray(events).view(raw)
        try:
            replies = self._exchange({w: ("band_run", n, self._t0, bool(record_tot)) for w in workers})
        except BaseException:
            self._broken = True
            raise
        self._t_hi = max(self._t_hi, int(events["t"][-1]))
        cap = self.capacity
        parts = np.array([(w * cap, w * cap + replies[w][1]) for w in workers], np.int64).reshape(-1, 2)
        end = merge_by_step(self._depth.view(np.uint32), self._depth["step"], parts, into.view(np.uint32), offset, 7)
        n_tot = 0
        if record_tot:
            n_tot = sum(replies[w][2] for w in workers)
            if len(self._tot) < n_tot:
                self._tot = np.empty(max(n_tot, 2 * len(self._tot)), TOT_DTYPE)
            spikes = np.array([(4 * w * cap, 4 * w * cap + replies[w][2]) for w in workers], np.int64).reshape(-1, 2)
            merge_by_step(self._spikes.view(np.uint8), self._spikes["step"], spikes, self._tot.view(np.uint8), 0,
                          TOT_DTYPE.itemsize)
        return end, n_tot
