"""Workers for ``fixed`` and ``float``: the sensor cut into bands of rows that run in threads.

A band holds rows ``[y0, y1)`` of the network (``tofnet.compiler.bands``). The paper's chain
runs per band through the fused kernel (``BandedKernel``): each band's kernel is given the
packet's events of its rows widened by the network's input reach (its halo), filters them
all, and triggers, counts and emits for its own pixels only, so every count and estimate is
the one-kernel run's. Any other graph runs model by model, each core-placed process as one
instance per band fed the spikes of its halo (``local_placements``: the ``multiproc`` stand-in,
run in threads), and each event-reading model that runs in bands (the time surface) as one
instance per band fed its rows' events (``BandedReader``); other host processes run whole (the
summary names them). Threads, not processes: the kernels release the
GIL (numba ``nogil``) and share the packet without copies (docs/performance.md, "Workers").
"""

from __future__ import annotations

import threading
import weakref
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from typing import Callable, Sequence

import numpy as np

from tofnet.backends._workers import _Worker
from tofnet.backends.band_merge import BandsBase, merge_share, merged_by_step, rows_read
from tofnet.backends.remote import Placement, RemoteModel, summed_counts
from tofnet.compiler.bands import Band
from tofnet.compiler.partition import halo_of, receptive_offsets
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE
from tofnet.kernels.bands import row_load, select_rows, touch
from tofnet.kernels.input_filter import NEVER
from tofnet.kernels.kernel_config import KernelConfig, Region
from tofnet.kernels.region import UNSORTED, TimeOfTravelKernel
from tofnet.machine import cpu_count
from tofnet.models.base import Model, holds_whole_numbers, splits_into_regions
from tofnet.models.contract import run_model

#: Packets with fewer events run their bands one after the other in the caller's thread: handing
#: work to another thread and back (~0.15-0.3 ms on a virtual machine) costs more than it saves there
#: (the time surface's bands, 1280x720: 0.61-0.70x of one worker at 8,192-16,384 events in threads,
#: ~0.9x one after the other; docs/performance.md, "Streams: packet size").
SERIAL_BELOW = 1 << 15
#: A stream of the fused kernel whose first packet has fewer events keeps one whole-sensor kernel: two bands
#: in threads break even at ~2^17 events per packet (0.86-1.09x of one kernel there in different runs, 1.2-1.4x
#: at 2^18; 1280x720, 2 CPUs), so 2^18 keeps a margin; 1 ms packets of a 20 M ev/s sensor hold ~20,000 events.
#: A ``run`` asks for bands whatever its packets (docs/performance.md, "Streams: packet size").
FUSED_BANDS_FROM = 1 << 18
#: The block by which ``touch`` shares fresh pages between threads: a transparent huge page (numpy
#: asks for them on large arrays), whose first touch is one fault, paid by one thread.
HUGE_PAGE = 1 << 21


def resolve_workers(value, who: str = "workers") -> int:
    """Workers asked for: a positive whole number, or ``0`` / ``"auto"`` for the machine's CPUs."""
    if value is None:
        return 1
    if value == "auto" or (isinstance(value, int) and not isinstance(value, bool) and value == 0):
        return cpu_count()
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise BackendError(f"{who} must be a whole number of workers (0 or 'auto': one per CPU), got {value!r}")
    return value


def sampled_row_load(events: np.ndarray, height: int) -> np.ndarray | None:
    """Events per row (``height`` rows) among a sample of about 65536 of ``events`` (a million took
    10-17 ms), for cutting bands by load; None without events (equal heights then)."""
    if not len(events):
        return None
    return row_load(events, height, max(1, len(events) >> 16))


def threads_for(bands: int) -> int:
    """Threads that run ``bands`` bands: one per band, at most one per CPU."""
    return max(1, min(bands, cpu_count()))


class BandPool:
    """Threads started once (per stream) that run one job per band; the caller's thread runs the first
    share itself. ``threads`` 1: no thread at all."""

    def __init__(self, threads: int):
        self.threads = threads
        self._pool = ThreadPoolExecutor(threads - 1, thread_name_prefix="tofnet-band") if threads > 1 else None
        if self._pool is not None:
            weakref.finalize(self, self._pool.shutdown, wait=False)

    def run(self, job: Callable[[int], object], jobs: int, serial: bool = False) -> list:
        """``job(b)`` for every ``b < jobs``, the results in order; shares of consecutive jobs per thread."""
        if self._pool is None or serial or jobs < 2:
            return [job(b) for b in range(jobs)]
        shares = np.array_split(np.arange(jobs), min(self.threads, jobs))
        futures = [self._pool.submit(lambda share=share: [job(int(b)) for b in share]) for share in shares[1:]]
        first = [job(int(b)) for b in shares[0]]
        rest = [f.result() for f in futures]  # every thread finishes before an error propagates
        return first + [r for part in rest for r in part]

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


class BandedKernel(BandsBase):
    """The fused kernel over ``bands`` in threads (``TimeOfTravelKernel``'s streaming API, as ``FusedStream`` uses it).

    Estimates and time-of-travel spikes of a call are those of one whole-sensor kernel, merged
    in the canonical order (``run_events`` sorts always: the trigger-event order of a one-kernel
    ``feed`` is not kept across bands); counts are the bands' sums.
    """

    def __init__(self, config: KernelConfig, bands: Sequence[Band], reach: int, threads: int, t0_us: int = 0):
        super().__init__(config, t0_us)
        self._planned, self._reach, self._threads = list(bands), reach, threads
        self.kernels: list[TimeOfTravelKernel] = []  # built for the first packet (``_build``)
        self._pool: BandPool | None = None
        self._lock = threading.Lock()
        self._scratch = np.empty(0, DEPTH_DTYPE)
        self._touched = (0, 0, 0)  # an output buffer's address and length, and the bytes touched in it
        self._estimates = 0  # of the latest packet
        self.facts = {"workers": 1, "bands": []}
        #: A first packet of fewer events keeps one band (``_build``); ``run`` sets 0: its packets are large.
        self.one_band_below = FUSED_BANDS_FROM

    def _build(self, packet: int) -> None:
        """The bands' kernels, for a first packet of ``packet`` events: a stream fed smaller packets than
        ``one_band_below`` (1 ms of a 20 M ev/s sensor) keeps one whole-sensor kernel, as one worker would:
        for them bands cost more than they save (docs/performance.md, "Streams: packet size")."""
        width, height = self.config.sensor_size
        self.bands = self._planned if packet >= self.one_band_below else [(0, height)]
        self._keep = [rows_read(band, self._reach, height, b == 0) for b, band in enumerate(self.bands)]
        self._index = np.empty((len(self.bands), 0), np.int64)  # per band, the positions of its events
        self._pool = BandPool(min(self._threads, len(self.bands)))
        self._barrier = threading.Barrier(self._pool.threads)
        # each band's state is built (and its pages touched) by the thread that runs it
        self.kernels = self._pool.run(lambda b: TimeOfTravelKernel(self.config, Region(0, width, *self.bands[b]),
                                                                   self._t0), len(self.bands))
        if self._t_hi != NEVER:
            for kernel in self.kernels:
                kernel.promise(self._t_hi)
        self.facts = {"workers": self._pool.threads, "bands": [list(b) for b in self.bands]}
        if len(self.bands) < len(self._planned):
            self.facts["one_band"] = (f"the first packet held {packet:,} events; bands pay from "
                                      f"{self.one_band_below:,} (docs/performance.md)")

    def prepare(self, packet: int) -> None:
        """Build the bands' kernels now, for packets of ``packet`` events (else the first packet builds them)."""
        if not self.kernels:
            self._build(packet)

    @BandsBase.t0_us.setter
    def t0_us(self, value: int) -> None:
        self._t0 = int(value)
        for kernel in self.kernels:
            kernel.t0_us = value

    def _band_counts(self) -> list[tuple]:
        return [(k.accepted, k.drops, k.tot_spikes, k.outcomes) for k in self.kernels]

    def buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.kernels[0].buffers() if len(self.kernels) == 1 else super().buffers()

    def promise(self, until_us: int) -> None:
        self._t_hi = max(self._t_hi, int(until_us))
        for kernel in self.kernels:
            kernel.promise(until_us)

    def join_packets(self, depth: np.ndarray, seams: list[int]) -> np.ndarray:
        return self.kernels[0].join_packets(depth, seams) if self.kernels else depth

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()

    def run_events(self, events: np.ndarray, velocity, into: np.ndarray | None = None, offset: int = 0,
                   record_tot: bool = False, span: tuple[int, int] | None = None,
                   canonical: bool = True) -> tuple[int, int]:
        """As ``TimeOfTravelKernel.run_events``; with several bands the estimates are in the canonical order.

        One hand-over per packet: each thread touches its share of the output's fresh pages, lists
        and runs its bands (each band lists its events of the whole packet, ``select_rows``), waits
        for the others and merges its share of the steps."""
        into, offset = self._output(events, into, offset)
        n = len(events)
        if n == 0:
            return offset, 0
        if not self.kernels:
            self._build(n)
        if len(self.kernels) == 1:  # one band: the one-worker path, nothing to list or merge
            return self.kernels[0].run_events(events, velocity, into, offset, record_tot, span, canonical)
        bands = len(self.kernels)
        threads = self._pool.threads if n >= SERIAL_BELOW else 1  # a small packet: no hand-over
        if len(self._scratch) < n * bands:  # band b writes from b * n: at most one estimate per event
            self._scratch = np.empty(max(n * bands, 2 * len(self._scratch)), DEPTH_DTYPE)
        if self._index.shape[1] <= n:
            self._index = np.empty((bands, max(n + 1, 2 * self._index.shape[1])), np.int64)
        scratch, index, t = self._scratch, self._index, events["t"]
        span = int(t[0]), int(t[-1])
        results: list = [None] * (bands + threads)  # per band its ends or its error, then per thread its merge's end
        share = np.array_split(np.arange(bands), threads)
        fresh = self._fresh(into, offset, n, threads)

        def velocity_locked(first, count):
            with self._lock:
                return velocity(first, count)

        def job(k: int) -> None:
            """Thread k's bands listed and run, then (every band run) share k of the merge; errors are
            kept in ``results`` (every band checks the packet's time order), and every thread waits."""
            try:
                if fresh is not None:
                    touch(*fresh, k, threads, HUGE_PAGE)
                for b in share[k]:
                    try:
                        m = select_rows(events, self._keep[b], index[b])
                        if m < 0:
                            raise BackendError(UNSORTED)
                        results[b] = self.kernels[b].run_events(events, velocity_locked, scratch, b * n, record_tot,
                                                                span, True, index[b, :m])
                    except BaseException as error:  # noqa: B036 - re-raised by the caller, once all are done
                        results[b] = error
            except BaseException as error:  # noqa: B036 - as above
                results[bands + k] = error
            self._wait(threads)
            if any(isinstance(r, BaseException) for r in results):
                return
            parts = [(b * n, e) for b, (e, _) in enumerate(results[:bands])]
            results[bands + k] = merge_share(scratch, parts, into, offset, k, threads)

        self._pool.run(job, threads, threads < 2)
        errors = [e for e in results if isinstance(e, BaseException)]
        if errors:
            if len(errors) != bands or any(str(e) != UNSORTED for e in errors):
                self._broken = True  # some bands ran the packet, others did not
            raise errors[0]  # every band refused it: nothing changed
        self._t_hi = max(self._t_hi, span[1])
        end = max(results[bands:])
        self._estimates = end - offset
        if not record_tot:
            return end, 0
        tots = [k.buffers()[2][:t] for k, (_, t) in zip(self.kernels, results[:bands])]
        bounds = np.cumsum([0] + [len(t) for t in tots])
        return end, self._merged_tot(np.concatenate(tots), np.stack([bounds[:-1], bounds[1:]], 1))

    def _wait(self, threads: int) -> None:
        """Wait for every thread of the packet (none when one runs it); an interrupted wait breaks the
        barrier, so that no thread waits for ever, and the kernels' state with it."""
        if threads < 2:
            return
        try:
            self._barrier.wait()
        except BaseException:
            self._broken = True
            self._barrier.abort()
            raise

    def _fresh(self, into: np.ndarray, offset: int, n: int, parts: int) -> tuple | None:
        """``(bytes, address, lo, hi)``: the bytes of ``into`` this packet's merge may be first to touch
        (past what earlier packets touched, at least ``parts`` huge pages at a time, within the
        packet's room), for ``touch``; None when there are none. On this kind of machine the first
        touch of fresh memory is the dearest part of the merge, and one thread would pay it alone
        (the one writing the furthest): docs/performance.md, "Workers"."""
        if parts < 2 or not into.flags.c_contiguous:
            return None
        size, address = into.dtype.itemsize, into.ctypes.data
        if self._touched[:2] != (address, len(into)):
            self._touched = (address, len(into), 0)
        room = (offset + n) * size
        lo = max(self._touched[2], offset * size)
        want = min(room, (offset + 2 * self._estimates + 4096) * size)
        if want <= lo:
            return None
        hi = min(room, max(want, lo + parts * HUGE_PAGE))
        self._touched = (address, len(into), hi)
        return into.view(np.uint8), address, lo, hi


class BandedReader(Model):
    """An event-reading model (``Model.runs_in_bands``) run as one instance per band of rows: each is fed
    every event (and keeps what its rows need: the time surface's, ``TimeSurfaceModel._columns``) and
    counts and answers for its rows, the bands run a range of steps in ``pool``'s threads,
    and their records (each sorted by step) are merged by step in band order, the canonical order (a
    port per thread)."""

    reads_events = True

    def __init__(self, process, model_class, bands: Sequence[Band], ctx, pool: BandPool):
        super().__init__(process, ctx)
        width = ctx.sensor_size[0]
        self.pool = pool
        # each band's state is built (and its pages touched) by the thread that runs it
        self.models = pool.run(lambda b: model_class(process, replace(ctx, region=Region(0, width, *bands[b]))),
                               len(bands))
        self._fed = 0  # events fed since the last run: a few run in the caller's thread

    def feed(self, events: np.ndarray) -> None:
        # each band keeps its own copy of the columns of the packet's events it runs, made in its thread
        self.pool.run(lambda b: self.models[b].feed(events), len(self.models), len(events) < SERIAL_BELOW)
        self._fed += len(events)

    def complete_until(self) -> int | None:
        return self.models[0].complete_until()  # every band was fed the same events

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        answers = self.pool.run(lambda b: run_model(self.process, self.models[b], first, end, inputs), len(self.models),
                                self._fed < SERIAL_BELOW)
        self._fed = 0
        ports = list(answers[0])

        def merged(i: int) -> np.ndarray:
            parts = [a[ports[i]] for a in answers]
            return merged_by_step(parts, parts[0].dtype)

        # a port per thread (the copies and the merge release the GIL), unless there is too little to hand over
        records = sum(len(a[port]) for a in answers for port in ports)
        return dict(zip(ports, self.pool.run(merged, len(ports), records < SERIAL_BELOW)))

    def counts(self) -> dict[str, int]:
        return summed_counts(model.counts() for model in self.models)

    def get_var(self, name: str, step: int) -> np.ndarray:
        return np.concatenate([model.get_var(name, step) for model in self.models], axis=-2)  # bands of rows

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        for model in self.models:
            model.set_var(name, value, step)

    def set_param(self, name: str, value) -> None:
        for model in self.models:
            model.set_param(name, value)


def band_placer(bands: Sequence[Band], threads: int):
    """``(place, pool, facts)`` for a ``GraphExecutor`` running ``bands``: each core-placed process whose
    model can hold a region becomes one instance per band behind a ``RemoteModel`` whose exchange
    runs the bands in ``pool``'s threads, and each event-reading one that runs in bands one instance
    per band behind a ``BandedReader``; any other process runs whole. ``facts`` (updated as the
    executor places processes) names both kinds, for ``RunResult.extra``."""
    pool = BandPool(min(threads, len(bands)))
    workers = [_Worker(b) for b in range(len(bands))]
    exchange = band_exchange(pool, workers)
    facts = {"workers": pool.threads, "bands": [list(b) for b in bands], "banded": [], "whole": []}

    def place(process, model_class, ctx):
        if getattr(model_class, "reads_events", False) and getattr(model_class, "runs_in_bands", False) \
                and not holds_whole_numbers(process):
            if process.name not in facts["banded"]:
                facts["banded"].append(process.name)
            return BandedReader(process, model_class, bands, ctx, pool)
        if process.placement != "core" or not splits_into_regions(process, model_class):
            if process.name not in facts["whole"]:
                facts["whole"].append(process.name)
            return model_class(process, ctx)
        placements = []
        for placement, model in band_placements(process, model_class, bands, ctx):
            workers[placement.worker].models[placement.key] = model
            placements.append(placement)
        if process.name not in facts["banded"]:
            facts["banded"].append(process.name)
        return RemoteModel(process, model_class, placements, exchange)

    return place, pool, facts


def band_exchange(pool: BandPool, workers: list) -> Callable[[dict[int, tuple]], dict[int, tuple]]:
    """``RemoteModel``'s exchange, answered by the bands' message handlers (``_Worker``) in ``pool``'s threads,
    or one after the other in the caller's when the runs carry fewer than ``SERIAL_BELOW`` records (a 1 ms
    packet's spikes: handing them over costs more than the second core saves)."""
    def exchange(messages: dict[int, tuple]) -> dict[int, tuple]:
        keys = sorted(messages)
        records = sum(len(r) for m in messages.values() if m[0] == "run" for _, inputs in m[1]
                      for r in inputs.values())
        replies = pool.run(lambda i: workers[keys[i]].handle(messages[keys[i]]), len(keys), records < SERIAL_BELOW)
        return dict(zip(keys, replies))
    return exchange


def band_placements(process, model_class, bands: Sequence[Band], ctx) -> list[tuple[Placement, object]]:
    """One instance of ``process`` per band (its rows), fed the spikes of its halo (from the process's
    receptive offsets, as the compiler's cores are)."""
    width, height = process.sensor_size
    offsets = receptive_offsets(process)
    out = []
    for b, (y0, y1) in enumerate(bands):
        rect = (0, y0, width, y1)
        model = model_class(process, replace(ctx, region=Region(0, width, y0, y1)))
        out.append((Placement((process.name, b), b, tuple(halo_of(rect, offsets, (width, height))), rect), model))
    return out
