"""The event-driven backends: ``fixed`` (bit-exact integers) and ``float``, one shared kernel.

Both run the whole sensor as one region of ``tofnet.kernels.region`` and differ
only in the depth arithmetic (docs/fixed_point.md). Work is proportional to events;
a run is a stream fed in packets, so memory does not grow with the recording (apart
from the estimates ``run`` collects).
"""

from __future__ import annotations

import time

import numpy as np

from tofnet.backends.base import DROP_REASONS, REJECT_REASONS, Backend, ProgressCallback, RunResult
from tofnet.backends.runtime import as_pipeline, intrinsics_of, start_time_us, velocity_source_of, velocity_table
from tofnet.errors import BackendError, DataError
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE, TOT_DTYPE
from tofnet.io.recording import Intrinsics, Recording, VelocitySource
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS, FixedPointFormat
from tofnet.kernels.region import KernelConfig, KernelOutput, TimeOfTravelKernel, copy_records

#: Events per packet in ``run`` (bounded memory; ~0.1 s of a busy 240x180 recording).
DEFAULT_PACKET_EVENTS = 1 << 17
#: Initial size of ``run``'s result buffer in estimates (at most one per event); 4M x 28 B
#: of address space, resident only where written.
RESULT_CAPACITY = 1 << 22
#: Velocity updates computed ahead of the stream, so that a packet rarely pays for them.
VELOCITY_LOOKAHEAD = 1024


class Stream:
    """A network running on a live event stream: ``feed`` packets in time order, then ``close``.

    Packets may be split anywhere (even inside a timestep); the estimates equal those
    of one run over the concatenated events. ``t0_us`` None: the first event fed.
    Memory is fixed by the sensor and the largest packet, whatever the recording's length.
    """

    def __init__(self, backend: str, config: KernelConfig, pipeline, velocity_source: VelocitySource,
                 t0_us: int | None, record_tot: bool = False):
        self.backend = backend
        self.pipeline = pipeline
        self.kernel = TimeOfTravelKernel(config, t0_us=t0_us or 0)
        self.velocity_source = velocity_source
        self.t0_us = t0_us
        self.record_tot = record_tot
        #: Time-of-travel spikes of the latest ``feed`` (``TOT_DTYPE``) when ``record_tot``.
        self.tot: np.ndarray | None = None
        self._events_in = 0
        self._table: tuple[int, np.ndarray] = (0, np.zeros((0, 3)))
        self._started = time.perf_counter()
        self._closed = False

    def _rows(self, first: int, count: int) -> tuple[np.ndarray, int]:
        """Velocity updates ``first .. first+count-1`` (``VelocityRows``): the cached table when it
        covers them, else a new one computed ``VELOCITY_LOOKAHEAD`` updates ahead."""
        start, table = self._table
        if start <= first and first + count <= start + len(table):
            return table, start
        p = self.pipeline
        try:
            table = velocity_table(self.velocity_source, self.t0_us, p.timestep_us, p.update_every,
                                   max(count, VELOCITY_LOOKAHEAD), first)
        except (BackendError, DataError):  # e.g. not finite beyond the rows asked for: compute only those
            table = velocity_table(self.velocity_source, self.t0_us, p.timestep_us, p.update_every, count, first)
        self._table = (first, table)
        return table, first

    def _start(self, events: np.ndarray) -> bool:
        """Checks and counting common to both feeds; False for an empty packet."""
        if self._closed:
            raise BackendError("stream is closed")
        if events.dtype != EVENT_DTYPE:
            raise BackendError(f"events must have dtype {EVENT_DTYPE}, got {events.dtype}")
        n = len(events)
        self._events_in += n
        if n and self.t0_us is None:
            self.t0_us = self.kernel.t0_us = int(events["t"][0])
        return n > 0

    def feed(self, events: np.ndarray) -> np.ndarray:
        """Depth estimates (``DEPTH_DTYPE``) produced by ``events`` (``EVENT_DTYPE``, time-ordered)."""
        if not self._start(events):
            self.tot = np.empty(0, TOT_DTYPE) if self.record_tot else None
            return np.empty(0, DEPTH_DTYPE)
        into = np.empty(len(events), DEPTH_DTYPE)  # the kernel writes the caller's array: no copy
        end, n_tot = self.kernel.run_events(events, self._rows, into, 0, self.record_tot)
        self.tot = copy_records(self.kernel.buffers()[2][:n_tot]) if self.record_tot else None
        return into[:end]

    def feed_into(self, events: np.ndarray, into: np.ndarray, offset: int) -> KernelOutput | None:
        """Like ``feed``, but write the estimates to ``into[offset:]`` (room for ``len(events)``).

        Returns the kernel's output (``depth`` a view of ``into``; ``tot`` valid until the next
        call, no ``z_raw``), None for an empty packet. Spares a copy when the caller collects the estimates.
        """
        if not self._start(events):
            return None
        return self.kernel.process_events(events, self._rows, record_tot=self.record_tot, into=into, offset=offset,
                                          copy=False)

    def close(self) -> RunResult:
        """The counts so far (``depth`` is empty: ``feed`` returned the estimates)."""
        self._closed = True
        kernel = self.kernel
        fmt = kernel.config.fixed
        return RunResult(
            backend=self.backend, depth=np.empty(0, DEPTH_DTYPE), events_in=self._events_in,
            accepted=kernel.accepted, dropped={reason: int(c) for reason, c in zip(DROP_REASONS, kernel.drops)},
            rejected={reason: int(c) for reason, c in zip(REJECT_REASONS, kernel.rejected)},
            tot_spikes=kernel.tot_spikes,
            steps=kernel.current_step + 1 + self.pipeline.latency_steps,
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
        for lo in range(0, total, self.packet_events):
            packet = events[lo:lo + self.packet_events]
            buffer, offset = depth.reserve(len(packet))
            out = stream.feed_into(packet, buffer, offset)  # the kernel writes the estimates in place
            if out is not None:
                depth.commit(len(out.depth))
                if record_tot:
                    tot.add(out.tot)
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

    def reserve(self, n: int) -> tuple[np.ndarray, int]:
        """``(buffer, offset)`` with room for ``n`` records at ``offset``; ``commit`` how many were written."""
        end = self._size + n
        if end > len(self._buffer):
            grown = np.empty(max(end, 2 * len(self._buffer)), self._buffer.dtype)
            raw = np.dtype((np.void, grown.dtype.itemsize))
            grown[:self._size].view(raw)[:] = self._buffer[:self._size].view(raw)
            self._buffer = grown
        return self._buffer, self._size

    def commit(self, n: int) -> None:
        self._size += n

    def add(self, part: np.ndarray) -> None:
        buffer, offset = self.reserve(len(part))
        raw = np.dtype((np.void, part.dtype.itemsize))  # packed records copy field by field, bytes do not
        buffer[offset:offset + len(part)].view(raw)[:] = part.view(raw)
        self.commit(len(part))

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
