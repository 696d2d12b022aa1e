"""What every set of band kernels shares: the fused kernel's streaming API over bands, and the merge.

``BandsBase`` is ``TimeOfTravelKernel``'s streaming API (as ``FusedStream`` uses it) for kernels
that hold one band of rows each, wherever they run (threads: ``bands.BandedKernel``; worker
processes: ``shared_bands.SharedBandKernel``). A subclass reports its bands' counts and runs a
packet; this class checks the packet, sums the counts and merges the bands' outputs, each sorted
by step, in the canonical order (by step, then band: bands are strips of rows from the top).
"""

from __future__ import annotations

import numpy as np

from tofnet.compiler.bands import Band, halo_rows
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, TOT_DTYPE
from tofnet.kernels.bands import merge_by_step, merge_cuts
from tofnet.kernels.input_filter import ACCEPTED, NEVER
from tofnet.kernels.kernel_config import KernelConfig, KernelOutput
from tofnet.kernels.time_of_travel import N_REASONS
from tofnet.models.base import concat


def words(records: np.ndarray) -> tuple[np.ndarray, int]:
    """A contiguous record array as flat words and the words per record (a view): 32-bit words when
    the records are whole words (depth records: 7), else bytes."""
    size = records.dtype.itemsize
    word = np.uint32 if size % 4 == 0 else np.uint8
    return records.view(word).reshape(-1), size // np.dtype(word).itemsize


def rows_read(band: Band, reach: int, height: int, outside: bool) -> np.ndarray:
    """Per row ``y`` (uint8, 65536 entries: every ``y`` an event can have): 1 when band ``band`` reads
    the row's events (its rows widened by ``reach``), and with ``outside`` (the first band: it counts
    them) for the rows past the sensor."""
    keep = np.zeros(1 << 16, np.uint8)
    lo, hi = halo_rows(band, reach, height)
    keep[lo:hi] = 1
    if outside:
        keep[height:] = 1
    return keep


def merge(source: np.ndarray, parts: np.ndarray, into: np.ndarray, offset: int) -> int:
    """Copy the records ``source[lo:hi]`` of each part (rows ``lo, hi``; each sorted by step) to
    ``into[offset:]`` by step, parts in order within a step; returns the end in ``into``."""
    flat, width = words(source)
    return merge_by_step(flat, source["step"], np.asarray(parts, np.int64).reshape(-1, 2), words(into)[0], offset,
                         width)


def merged_by_step(parts: list[np.ndarray], dtype: np.dtype) -> np.ndarray:
    """The records of ``parts`` (each sorted by step) in one array sorted by step, the parts in order within
    a step, in time linear in the records: the canonical order when the parts are bands of rows from the
    top, each in it (a part out of step order still gives every record once, for ``canonical`` to sort)."""
    parts = [p for p in parts if len(p)]
    if len(parts) < 2:
        return concat(parts, dtype)
    source = concat(parts, dtype)
    bounds = np.cumsum([0] + [len(p) for p in parts])
    out = np.empty(len(source), source.dtype)
    merge(source, np.stack([bounds[:-1], bounds[1:]], 1), out, 0)
    return out


def merge_share(source: np.ndarray, parts: np.ndarray, into: np.ndarray, offset: int, share: int, shares: int) -> int:
    """Share ``share`` of ``shares`` of ``merge(source, parts, into, offset)``: the records of its steps
    (``merge_cuts``: every share cuts the same) to their place in ``into``; returns the share's end.
    The shares run side by side (threads or processes), each writing its own part of ``into``."""
    parts = np.asarray(parts, np.int64).reshape(-1, 2)
    cuts = merge_cuts(source["step"], parts, shares)
    before = int((cuts[share] - cuts[0]).sum())
    return merge(source, np.stack([cuts[share], cuts[share + 1]], 1), into, offset + before)


class BandsBase:
    """Band kernels behind one kernel's API. Subclasses implement ``_band_counts`` and ``run_events``."""

    def __init__(self, config: KernelConfig, t0_us: int = 0):
        self.config = config
        self._t0 = int(t0_us)
        self._t_hi = NEVER  # the latest event time fed or promised (every band checks its part too)
        self._out = np.empty(0, DEPTH_DTYPE)
        self._tot = np.empty(0, TOT_DTYPE)
        self._broken = False
        #: What a run reports about how it ran (``RunResult.extra``).
        self.facts: dict = {}

    def _band_counts(self) -> list[tuple]:
        """Per band: ``(accepted, drops, time-of-travel spikes, outcomes)``."""
        raise NotImplementedError

    @property
    def t0_us(self) -> int:
        return self._t0

    @t0_us.setter
    def t0_us(self, value: int) -> None:
        self._t0 = int(value)

    @property
    def accepted(self) -> int:
        return sum(c[0] for c in self._band_counts())

    @property
    def drops(self) -> np.ndarray:
        counts = self._band_counts()
        return np.sum([c[1] for c in counts], axis=0) if counts else np.zeros(ACCEPTED, np.int64)

    @property
    def tot_spikes(self) -> int:
        return sum(c[2] for c in self._band_counts())

    @property
    def outcomes(self) -> np.ndarray:
        counts = self._band_counts()
        return np.sum([c[3] for c in counts], axis=0) if counts else np.zeros(N_REASONS + 1, np.int64)

    def buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._out, np.empty(0, np.int64), self._tot

    def process_events(self, events: np.ndarray, velocity, *, record_tot: bool = False, copy: bool = True,
                       into: np.ndarray | None = None, offset: int = 0) -> KernelOutput:
        spikes_before = self.tot_spikes
        end, n_tot = self.run_events(events, velocity, into, offset, record_tot)
        depth = self.buffers()[0][:end] if into is None else into[offset:end]
        tot = self.buffers()[2][:n_tot] if record_tot else None
        if copy:
            depth, tot = depth.copy(), (tot.copy() if tot is not None else None)
        return KernelOutput(depth, np.empty(0, np.int64), tot, self.tot_spikes - spikes_before)

    def run_events(self, events: np.ndarray, velocity, into: np.ndarray | None = None, offset: int = 0,
                   record_tot: bool = False, span=None, canonical: bool = True) -> tuple[int, int]:
        raise NotImplementedError

    # -- for subclasses --------------------------------------------------------------------------
    def _output(self, events: np.ndarray, into: np.ndarray | None, offset: int) -> tuple[np.ndarray, int]:
        """Where a packet's estimates go: ``into`` (checked) or the internal buffer (grown)."""
        if self._broken:
            raise BackendError("kernel state is invalid after an earlier error; start a new one")
        n = len(events)
        if into is None:
            if len(self._out) < n:
                self._out = np.empty(max(n, 2 * len(self._out)), DEPTH_DTYPE)
            return self._out, 0
        if len(into) < offset + n:
            raise BackendError(f"output buffer holds {len(into)} estimates, {offset + n} may be written")
        return into, offset

    def _merged_tot(self, source: np.ndarray, parts: np.ndarray) -> int:
        """The bands' time-of-travel spikes (``source[lo:hi]`` per part) merged into ``buffers()[2]``."""
        n_tot = int(sum(hi - lo for lo, hi in parts))
        if len(self._tot) < n_tot:
            self._tot = np.empty(max(n_tot, 2 * len(self._tot)), TOT_DTYPE)
        merge(source, parts, self._tot, 0)
        return n_tot
