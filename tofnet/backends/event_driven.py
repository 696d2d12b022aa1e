"""The event-driven backends: ``fixed`` (bit-exact integers) and ``float``, one shared kernel.

Both run the whole sensor as one region of ``tofnet.kernels.region`` and differ
only in the depth arithmetic (docs/fixed_point.md). Work is proportional to events;
a run is a stream fed in packets, so memory does not grow with the recording (apart
from the estimates ``run`` collects).
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from tofnet.backends.base import DROP_REASONS, REJECT_REASONS, Backend, ProgressCallback, RunResult
from tofnet.backends.runtime import as_pipeline, intrinsics_of, start_time_us, velocity_source_of, velocity_table
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE, TOT_DTYPE
from tofnet.io.recording import Intrinsics, Recording, VelocitySource
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS, FixedPointFormat
from tofnet.kernels.input_filter import InputFilter
from tofnet.kernels.region import KernelConfig, KernelOutput, TimeOfTravelKernel

#: Events per packet in ``run`` (bounded memory; ~0.1 s of a busy 240x180 recording).
DEFAULT_PACKET_EVENTS = 1 << 17
#: Largest velocity table computed for one kernel call; sparser packets are split.
MAX_VELOCITY_ROWS = 1 << 16
#: Initial size of ``run``'s result buffer in estimates (at most one per event); 4M x 28 B
#: of address space, resident only where written.
RESULT_CAPACITY = 1 << 22


class Stream:
    """A network running on a live event stream: ``feed`` packets in time order, then ``close``.

    Packets may be split anywhere (even inside a timestep); the estimates equal those
    of one run over the concatenated events. ``t0_us`` None: the first event fed.
    """

    def __init__(self, backend: str, config: KernelConfig, pipeline, velocity_source: VelocitySource,
                 t0_us: int | None, record_tot: bool = False):
        self.backend = backend
        self.pipeline = pipeline
        self.kernel = TimeOfTravelKernel(config)
        self.velocity_source = velocity_source
        self.t0_us = t0_us
        self.record_tot = record_tot
        #: Time-of-travel spikes of the latest ``feed`` (``TOT_DTYPE``) when ``record_tot``.
        self.tot: np.ndarray | None = None
        self._filter: InputFilter | None = None
        self._last_step = -1
        self._events_in = 0
        self._table: tuple[int, np.ndarray] | None = None
        self._started = time.perf_counter()
        self._closed = False

    def _open_filter(self, events: np.ndarray) -> InputFilter:
        p = self.pipeline
        if self.t0_us is None:
            self.t0_us = int(events["t"][0])
        return InputFilter(p.sensor_size, self.t0_us, p.timestep_us, p.refractory_us, p.refractory_per_polarity)

    def _velocity(self, first: int, count: int) -> np.ndarray:
        """Rows ``first .. first+count-1`` of the velocity table, reusing the last one when it covers them."""
        if self._table is not None:
            start, table = self._table
            if start <= first and first + count <= start + len(table):
                return table[first - start:first - start + count]
        p = self.pipeline
        table = velocity_table(self.velocity_source, self.t0_us, p.timestep_us, p.update_every, count, first)
        self._table = (first, table)
        return table

    def feed(self, events: np.ndarray) -> np.ndarray:
        """Depth estimates (``DEPTH_DTYPE``) produced by ``events`` (``EVENT_DTYPE``, time-ordered)."""
        parts, tots = [], []

        def keep(out) -> None:  # the kernel's views are overwritten by its next call
            parts.append(out.depth.copy())
            if self.record_tot:
                tots.append(out.tot.copy())

        self.feed_into(events, keep)
        if self.record_tot:
            self.tot = tots[0] if len(tots) == 1 else np.concatenate(tots) if tots else np.empty(0, TOT_DTYPE)
        return parts[0] if len(parts) == 1 else np.concatenate(parts) if parts else np.empty(0, DEPTH_DTYPE)

    def feed_into(self, events: np.ndarray, emit: Callable[[KernelOutput], None]) -> None:
        """Like ``feed``, but hand each kernel call's output to ``emit`` as views valid during the call.

        Spares a copy when the caller stores the estimates somewhere anyway (``run`` does).
        """
        if self._closed:
            raise BackendError("stream is closed")
        if events.dtype != EVENT_DTYPE:
            raise BackendError(f"events must have dtype {EVENT_DTYPE}, got {events.dtype}")
        self._events_in += len(events)
        if len(events) == 0:
            return
        if self._filter is None:
            self._filter = self._open_filter(events)
            self.kernel.t0_us = self.t0_us
        steps, xs, ys, ps = self._filter.feed(events)
        update_every = self.pipeline.update_every
        lo = 0
        while lo < len(steps):
            # Keep each call's velocity table small even when the spikes are sparse in time.
            first = (int(steps[lo]) + 1) // update_every
            hi = int(np.searchsorted(steps, (first + MAX_VELOCITY_ROWS) * update_every - 1, side="left"))
            hi = max(hi, lo + 1)  # only when the steps are unsorted, which the kernel refuses
            last = (int(steps[hi - 1]) + 1) // update_every
            table = self._velocity(first, max(last - first + 1, 1))
            emit(self.kernel.process(steps[lo:hi], xs[lo:hi], ys[lo:hi], ps[lo:hi], table, first,
                                     record_tot=self.record_tot, copy=False))
            lo = hi
        if len(steps):
            self._last_step = int(steps[-1])

    def close(self) -> RunResult:
        """The counts so far (``depth`` is empty: ``feed`` returned the estimates)."""
        self._closed = True
        flt = self._filter
        fmt = self.kernel.config.fixed
        return RunResult(
            backend=self.backend, depth=np.empty(0, DEPTH_DTYPE), events_in=self._events_in,
            accepted=flt.accepted if flt else 0,
            dropped=flt.dropped if flt else {reason: 0 for reason in DROP_REASONS},
            rejected={reason: int(c) for reason, c in zip(REJECT_REASONS, self.kernel.rejected)},
            tot_spikes=self.kernel.tot_spikes,
            steps=self._last_step + 1 + self.pipeline.latency_steps,
            t0_us=self.t0_us if self.t0_us is not None else 0, timestep_us=self.pipeline.timestep_us,
            latency_steps=self.pipeline.latency_steps, wall_time=time.perf_counter() - self._started,
            extra={"frac_bits": fmt.frac_bits, "payload_bits": fmt.payload_bits} if fmt else {},
        )


class EventDrivenBackend(Backend):
    """Runs a recording as a stream of packets of ``packet_events`` events."""

    def __init__(self, packet_events: int = DEFAULT_PACKET_EVENTS):
        if packet_events < 1:
            raise BackendError(f"packet_events must be positive, got {packet_events}")
        self.packet_events = int(packet_events)

    def _format(self) -> FixedPointFormat | None:
        return None

    def open_stream(self, compiled, *, intrinsics: Intrinsics, velocity_source: VelocitySource,
                    t0_us: int | None = None, record_tot: bool = False) -> Stream:
        """A ``Stream`` running ``compiled``; ``t0_us`` None: the pipeline's ``t0``, else the first event."""
        pipeline = as_pipeline(compiled)
        if t0_us is None and pipeline.t0 is not None:
            t0_us = int(round(pipeline.t0 * 1e6))
        config = KernelConfig.from_pipeline(pipeline, intrinsics, self._format())
        return Stream(self.name, config, pipeline, velocity_source, t0_us, record_tot)

    def run(self, compiled, recording: Recording, *, record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        started = time.perf_counter()
        pipeline = as_pipeline(compiled)
        stream = self.open_stream(pipeline, intrinsics=intrinsics_of(pipeline, recording),
                                  velocity_source=velocity_source_of(pipeline, recording),
                                  t0_us=start_time_us(pipeline, recording), record_tot=record_tot)
        events = recording.events
        total = len(events)
        depth = _Collector(DEPTH_DTYPE, min(total, RESULT_CAPACITY))
        tot = _Collector(TOT_DTYPE, 0)

        def emit(out) -> None:
            depth.add(out.depth)
            if record_tot:
                tot.add(out.tot)

        for lo in range(0, total, self.packet_events):
            stream.feed_into(events[lo:lo + self.packet_events], emit)
            if progress is not None:
                progress(min(lo + self.packet_events, total), total)
        result = stream.close()
        result.depth = depth.array()
        if record_tot:
            result.tot = tot.array()
        result.wall_time = time.perf_counter() - started
        return result


class _Collector:
    """Appends record arrays into one buffer that grows geometrically (one copy per record)."""

    def __init__(self, dtype: np.dtype, capacity: int):
        self._buffer = np.empty(capacity, dtype)
        self._size = 0

    def add(self, part: np.ndarray) -> None:
        end = self._size + len(part)
        if end > len(self._buffer):
            grown = np.empty(max(end, 2 * len(self._buffer)), self._buffer.dtype)
            grown[:self._size] = self._buffer[:self._size]
            self._buffer = grown
        self._buffer[self._size:end] = part
        self._size = end

    def array(self) -> np.ndarray:
        """The records so far. A view: pages of the buffer never written are never resident."""
        return self._buffer[:self._size]


class FloatBackend(EventDrivenBackend):
    """Event-driven float64 execution; equals the ``reference`` backend."""

    name = "float"
    arithmetic = "float"


class FixedBackend(EventDrivenBackend):
    """Event-driven, bit-exact integer depth path (docs/fixed_point.md).

    ``frac_bits`` F and ``payload_bits`` P: ``W = A t * dt / distance`` and ``Z`` are
    signed P-bit integers in units of ``2**-F`` m.
    """

    name = "fixed"
    arithmetic = "fixed"

    def __init__(self, frac_bits: int = DEFAULT_FRAC_BITS, payload_bits: int = DEFAULT_PAYLOAD_BITS,
                 packet_events: int = DEFAULT_PACKET_EVENTS):
        super().__init__(packet_events)
        self.format = FixedPointFormat(frac_bits, payload_bits)

    def _format(self) -> FixedPointFormat:
        return self.format
