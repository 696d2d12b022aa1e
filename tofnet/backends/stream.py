"""Any network on a live event stream: feed packets in time order, get what each produced, close."""

from __future__ import annotations

from typing import Callable, Iterable

import numpy as np

from tofnet.backends.base import ProgressCallback, RunResult
from tofnet.backends.graph import GraphExecutor
from tofnet.errors import BackendError
from tofnet.events import EVENT_DTYPE, MAX_TIME_US, polarity_problem
from tofnet.kernels.compilation import Stopwatch
from tofnet.models.base import concat
from tofnet.models.input import check_time_order

#: Events per packet when a backend runs a whole recording (bounded memory).
DEFAULT_PACKET_EVENTS = 1 << 17
#: The same with several workers: each packet is a hand-over to the bands and a wait for the slowest,
#: whose wake-ups cost ~0.1 ms each on a virtual machine; 4x larger packets were 1.1-1.6x faster with
#: 2 workers and no slower with 1 (docs/performance.md, "Packet size with workers").
BANDED_PACKET_EVENTS = 1 << 19


def packet_events_for(asked: int | None, workers: int, who: str = "backend") -> int:
    """Events per packet of a whole run: ``asked``, else the default for one or several ``workers``."""
    if asked is None:
        return BANDED_PACKET_EVENTS if workers > 1 else DEFAULT_PACKET_EVENTS
    if isinstance(asked, bool) or not isinstance(asked, int) or asked < 1:
        raise BackendError(f"{who}: packet_events must be a positive whole number, got {asked!r}")
    return asked


def primary_output(sinks: list[str], payloads: dict[str, str]) -> str | None:
    """The output ``feed`` returns: the only sink, else the only depth sink (None when ambiguous)."""
    if len(sinks) == 1:
        return sinks[0]
    depth = [s for s in sinks if payloads.get(s) == "depth"]
    return depth[0] if len(depth) == 1 else None


def check_events(events) -> tuple[int, int] | None:
    """Refuse a packet that is not an event array, whose times leave ``|t| < MAX_TIME_US``, or
    with a polarity other than 0/1 (``polarity_problem``, as the writers: the kernels would take any
    non-zero value as ON).

    Only the first and last times are looked at: a packet whose times are not in order is
    refused by the time-order check anyway, so in an accepted one they bound the rest.
    Returns those two times (µs), None for an empty packet.
    """
    if not isinstance(events, np.ndarray) or (events.dtype is not EVENT_DTYPE and events.dtype != EVENT_DTYPE) \
            or events.ndim != 1:
        got = events.dtype if isinstance(events, np.ndarray) else type(events).__name__
        raise BackendError(f"events must be a one-dimensional numpy array of dtype {EVENT_DTYPE} "
                           f"(tofnet.events.EVENT_DTYPE), got {got}")
    if not len(events):
        return None
    t = events["t"]
    first, last = int(t[0]), int(t[-1])
    if not (-MAX_TIME_US < first and last < MAX_TIME_US):
        raise BackendError(f"event times must satisfy |t| < 2**61 µs (docs/reliability.md), got {first} .. {last} µs")
    problem = polarity_problem(events["p"])
    if problem:
        raise BackendError(problem)
    return first, last


def check_packet(events, until_us) -> tuple[int, int] | None:
    """``check_events``, and a promise ``until_us`` (µs, or None) that is a whole number in the time
    range and later than the packet's last event; the packet's first and last times."""
    span = check_events(events)
    if until_us is None:
        return span
    if isinstance(until_us, bool) or not isinstance(until_us, (int, np.integer)):
        raise BackendError(f"until_us must be a whole number of µs, got {type(until_us).__name__} "
                           f"{str(until_us)[:40]!r}")
    if not -MAX_TIME_US < int(until_us) < MAX_TIME_US:
        raise BackendError(f"until_us={int(until_us)} µs is out of the time range (|t| < 2**61 µs, "
                           "docs/reliability.md)")
    if span is not None and span[1] >= until_us:
        raise BackendError(f"until_us={int(until_us)} µs but the packet holds events up to {span[1]} µs")
    return span


#: Steps one call may run at once (each step keeps a few records in memory until the call returns):
#: a promise ``until_us`` or an event further ahead is refused, before anything changes.
MAX_STEPS_AT_ONCE = 1 << 32


class GraphStream:
    """A network running on a stream of events; memory is fixed by the network, not the stream's length.

    ``feed(events)`` returns the records of the primary output (the one sink, or the one
    depth output) that the packet made complete; ``feed_all`` those of every sink and probe.
    A step is complete once an event of a later step arrived, or ``until_us`` says no event
    before that time will come. ``close()`` runs the steps still in flight and returns their
    outputs with the counts. A refused packet (wrong dtype, out of time order, a polarity not 0/1) leaves the
    stream as it was. ``t0_us`` None: step 0 starts at the first event fed.
    """

    def __init__(self, backend: str, build: Callable[[int], GraphExecutor], t0_us: int | None,
                 timestep_us: int, sinks: list[str], payloads: dict[str, str]):
        self.backend = backend
        self._build = build
        self.t0_us = t0_us
        self.timestep_us = timestep_us
        #: The stream's time: running, compiling kernels, and set-up (building the models and their state).
        self.clock = Stopwatch()
        self.executor: GraphExecutor | None = None
        if t0_us is not None:
            with self.clock.aside():
                self.executor = build(t0_us)
        self.sinks, self.payloads = sinks, payloads
        self.primary = primary_output(sinks, payloads)
        self._latest_us: int | None = None
        self._events_in = 0
        self._closed = False
        #: Backend facts added to the result (e.g. the fixed-point format).
        self.extra: dict = {}
        #: Called once when the stream closes or is given up (e.g. to stop a backend's threads).
        self.releases: list[Callable[[], None]] = []


    def check(self, events: np.ndarray, until_us: int | None = None) -> None:
        """Refuse (changing nothing) a packet ``feed_all`` would refuse: closed stream, not an event
        array, times out of range or order, a bad ``until_us``."""
        if self._closed:
            raise BackendError("stream is closed")
        span = check_packet(events, until_us)
        check_time_order(events, self._latest_us, "stream")
        ends = [int(until_us)] if until_us is not None else []
        if span is not None:
            ends.append(span[1])
            t0 = span[0] if self.t0_us is None else self.t0_us
        else:
            t0 = self.t0_us
        if ends and t0 is not None:
            ahead = (max(ends) - t0) // self.timestep_us - (self.executor.clock if self.executor else 0)
            if ahead > MAX_STEPS_AT_ONCE:
                raise BackendError(f"stream: this packet would run {ahead} steps at once (up to {max(ends)} µs), more "
                                   f"than 2**32; feed events or promise until_us nearer, a part at a time")

    def feed_all(self, events: np.ndarray, until_us: int | None = None) -> dict[str, np.ndarray]:
        """The records each sink and probe sent in the steps this packet completed."""
        self.check(events, until_us)
        if until_us is not None:
            until_us = int(until_us)
        if self.executor is None and len(events):
            self.t0_us = int(events["t"][0])
            with self.clock.aside():
                self.executor = self._build(self.t0_us)
        self._events_in += len(events)
        if len(events):
            self._latest_us = int(events["t"][-1])
        if until_us is not None:
            self._latest_us = max(self._latest_us or until_us, until_us)
        ex = self.executor
        if ex is None:
            return {}
        ex.feed(events)
        horizon = ex.complete_until()
        if until_us is not None and until_us >= self.t0_us:
            horizon = max(horizon or 0, (until_us - self.t0_us) // self.timestep_us)
        if horizon is None:
            return {}
        try:
            return ex.advance(horizon)
        except MemoryError:  # the steps up to the horizon run at once; this stream's state is lost
            self.abort()
            raise BackendError(f"stream: out of memory running steps {ex.clock} to {horizon} at once; feed events "
                               "or promise until_us nearer, a part at a time; the stream is closed") from None

    def feed(self, events: np.ndarray, until_us: int | None = None) -> np.ndarray:
        """The records of the primary output (depth, for the paper's network) this packet completed."""
        if self.primary is None:
            raise BackendError(f"the network has several outputs ({', '.join(self.sinks)}); use feed_all")
        out = self.feed_all(events, until_us)
        return out.get(self.primary, self._empty(self.primary))

    def _empty(self, name: str) -> np.ndarray:
        proc, _, port = name.partition(".")
        return self.executor.network.process(proc).port(port).spec.payload.empty() if self.executor else \
            np.empty(0, EVENT_DTYPE)

    def abort(self) -> None:
        """Give up the stream (after its caller failed): release what it holds, return nothing."""
        self._closed = True
        self._release()

    def _release(self) -> None:
        """Let the executor free what it holds outside this process (the lava backend's runtime), and
        run the backend's ``releases`` (e.g. stop its threads)."""
        release = getattr(self.executor, "release", None)
        hooks, self.releases = self.releases, []
        try:
            if release is not None:
                release()
        finally:
            for hook in hooks:
                hook()

    def end_step(self) -> int | None:
        """The step ``close`` runs to (exclusive): every output of every event fed is out by then;
        None before the stream has a start time (no event, no ``t0_us``)."""
        ex = self.executor
        if ex is None:
            return None
        last = ex.complete_until()
        last = -1 if last is None else last  # the step of the latest event; it is complete now
        return last + 1 + ex.drain_steps

    def close(self) -> RunResult:
        """Run the steps still in flight; their outputs (``outputs``) and every count so far."""
        if self._closed:
            raise BackendError("stream is closed")
        self._closed = True
        ex = self.executor
        if ex is None:
            raise BackendError("stream closed before any event: nothing ran (t0 unknown)")
        steps = max(ex.clock, self.end_step())  # a session may have run past the end: those steps ran too
        try:
            outputs = ex.advance(steps)
            counts = ex.counts()
        finally:
            self._release()
        latency = {name: ex.output_latency(name) for name in ex.sinks + ex.probes}
        return RunResult.of(ex.network, self.backend, outputs, counts, steps=steps, t0_us=self.t0_us,
                            timestep_us=self.timestep_us, latency=latency, extra=dict(self.extra)).timed_by(self.clock)


class Collected:
    """Records of several outputs gathered packet by packet, joined once at the end.

    With ``spill_dir``, an output that grows past ``limit_bytes`` goes on in a temporary
    file there (unlinked as soon as it is mapped): ``joined`` then returns a read-only
    memory map, so a long recording's outputs need disk, not memory.
    """

    def __init__(self, spill_dir=None, limit_bytes: int = 256 << 20):
        self.parts: dict[str, list[np.ndarray]] = {}
        self.spill_dir, self.limit_bytes = spill_dir, limit_bytes
        self._files: dict[str, tuple[object, np.dtype, int]] = {}  # name -> (open file, dtype, records)
        self._bytes: dict[str, int] = {}

    def add(self, outputs: dict[str, np.ndarray]) -> None:
        for name, records in outputs.items():
            if not len(records):
                continue
            if name in self._files:
                self._spill(name, [records])
                continue
            self.parts.setdefault(name, []).append(records)
            self._bytes[name] = self._bytes.get(name, 0) + records.nbytes
            if self.spill_dir is not None and self._bytes[name] > self.limit_bytes:
                self._spill(name, self.parts.pop(name))

    def _spill(self, name: str, parts: list[np.ndarray]) -> None:
        import tempfile
        if name not in self._files:
            handle = tempfile.NamedTemporaryFile(dir=self.spill_dir, prefix=f".tofnet-{name}.", suffix=".spill",
                                                 delete=True)
            self._files[name] = (handle, parts[0].dtype, 0)
        handle, dtype, count = self._files[name]
        for part in parts:
            handle.write(np.ascontiguousarray(part).tobytes())
            count += len(part)
        self._files[name] = (handle, dtype, count)

    def joined(self, names: Iterable[str], empty: Callable[[str], np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for name in names:
            if name in self._files:
                handle, dtype, count = self._files.pop(name)
                handle.flush()
                out[name] = np.memmap(handle.name, dtype=dtype, mode="r", shape=(count,))
                handle.close()  # deletes the file's name; the map keeps its pages until it is dropped
                continue
            parts = [p for p in self.parts.get(name, []) if len(p)]
            out[name] = concat(parts, None) if parts else empty(name)
        return out


def run_in_packets(stream: GraphStream, events: np.ndarray, packet_events: int,
                   progress: ProgressCallback | None) -> RunResult:
    """Feed ``events`` in packets; the result holds every output's records and the counts (timed by the
    stream's clock, its set-up apart)."""
    collected = Collected()
    total = len(events)
    for lo in range(0, total, packet_events):
        collected.add(stream.feed_all(events[lo:lo + packet_events]))
        if progress is not None:
            progress(min(lo + packet_events, total), total)
    result = stream.close()
    collected.add(result.outputs)
    result.outputs = collected.joined(result.payloads, stream._empty)
    return result.timed_by(stream.clock)
