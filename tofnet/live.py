"""Live sources: a network fed packet by packet as the events arrive, with the delay of each estimate measured.

A ``LiveSource`` hands over packets of one timestep (``packet_us``, 1 ms by default) as
they become complete on its clock, and says what time it is on that clock (``now_us``):

- ``ReplaySource``: a recording replayed at its recorded speed (``speed`` 1.0) or slower
  or faster; its clock is the file's, started at its first event when the replay starts.
- ``CameraSource``: a camera through faery's camera streams (``faery.events_stream_from_camera``);
  its clock is the camera's, tied to this computer's at the first packet.

``run_live`` opens a ``Session`` on the first packet and feeds each packet into it (the
same stream machinery as ``tofnet run``), hands the depth estimates to ``on_depth`` as
they come, and measures for each estimate the delay from the start of the timestep of the
event that caused it (the estimate's stamp minus its output's latency plus one step) to
the moment ``feed`` handed it back, on the source's clock: at most one step more than
from the event itself. A packet is *late* when it is fed more than one packet after it
was complete; with ``drop_when_late``, one fed more than ``late_tolerance_us`` (100 ms) after
has its events dropped (and counted), otherwise the run falls behind and says by how much. The
statistics (``LiveStats``, the delays in a fixed histogram): ``tofnet.live_stats``. Docs: docs/live.md.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Protocol

import numpy as np

from tofnet.errors import TofnetError
from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Recording
from tofnet.live_stats import LiveStats


class LiveSource(Protocol):
    """What ``run_live`` needs of a source of events arriving in real time."""

    packet_us: int
    #: The time of the first event when known before the first packet (a replay), else None.
    t0_us: int | None

    def metadata(self) -> Recording:
        """The camera (sensor size, intrinsics, poses or IMU if any), without events."""

    def packets(self) -> Iterator[tuple[np.ndarray, int]]:
        """``(events, until_us)`` once all events before ``until_us`` have arrived; blocks until then."""

    def now_us(self) -> float:
        """The present moment on the source's clock (µs)."""


def packet_bounds(t: np.ndarray, start_us: int, packet_us: int) -> tuple[np.ndarray, np.ndarray]:
    """Indexes splitting time-sorted ``t`` at every multiple of ``packet_us`` after ``start_us``, and the
    packets' ends (µs): packet ``i`` is ``t[cuts[i]:cuts[i + 1]]``, ending at ``ends[i]``."""
    first = (int(t[0]) - start_us) // packet_us
    last = (int(t[-1]) - start_us) // packet_us
    ends = start_us + packet_us * np.arange(first + 1, last + 2, dtype=np.int64)
    cuts = np.concatenate([[0], np.searchsorted(t, ends, side="left")])
    return cuts, ends


def _first_event_us(source, chunk_events: int) -> int | None:
    """The first event's time (µs) of a windowed source (its first chunk read once more by the replay)."""
    chunks = iter(source.chunks(chunk_events))
    try:
        return next((int(chunk["t"][0]) for chunk in chunks if len(chunk)), None)
    finally:
        getattr(chunks, "close", lambda: None)()


class ReplaySource:
    """A recording (an open ``EventSource``) replayed at ``speed`` times its recorded speed."""

    def __init__(self, source, speed: float = 1.0, packet_us: int = 1000, chunk_events: int = 1 << 16):
        if not (isinstance(speed, (int, float)) and np.isfinite(speed) and speed > 0):
            raise TofnetError(f"--speed: expected a number of times the recorded speed > 0, got {speed!r}")
        self.source, self.speed, self.packet_us, self.chunk_events = source, float(speed), int(packet_us), chunk_events
        self.first_us: int | None = None
        self._wall0: float | None = None
        # the session's t0: the first event (of the window), as tofnet run takes it, so both give the same steps
        self.t0_us = source.first_time() if source.window is None else _first_event_us(source, chunk_events)

    def metadata(self) -> Recording:
        return self.source.metadata()

    def now_us(self) -> float:
        if self._wall0 is None:
            return float("-inf")
        return self.first_us + (time.perf_counter() - self._wall0) * self.speed * 1e6

    def _wait_until(self, t_us: int) -> None:
        ahead = (t_us - self.now_us()) / self.speed * 1e-6
        if ahead > 0:
            time.sleep(ahead)

    def packets(self) -> Iterator[tuple[np.ndarray, int]]:
        carry = np.empty(0, EVENT_DTYPE)
        last_end = None
        for chunk in self.source.chunks(self.chunk_events):
            if not len(chunk):
                continue
            if self.first_us is None:  # the clock starts at the first event
                self.first_us = int(chunk["t"][0]) if self.t0_us is None else min(self.t0_us, int(chunk["t"][0]))
                self._wall0, last_end = time.perf_counter(), self.first_us
            events = np.concatenate([carry, chunk]) if len(carry) else chunk
            cuts, ends = packet_bounds(events["t"], self.first_us, self.packet_us)
            # The last packet may go on in the next chunk: keep it back.
            for i in range(len(ends) - 1):
                yield from self._empty_until(last_end, int(ends[i]) - self.packet_us)
                self._wait_until(int(ends[i]))
                yield events[cuts[i]:cuts[i + 1]], int(ends[i])
                last_end = int(ends[i])
            carry = events[cuts[-2]:]
        if len(carry):
            end = self.first_us + ((int(carry["t"][-1]) - self.first_us) // self.packet_us + 1) * self.packet_us
            yield from self._empty_until(last_end, end - self.packet_us)
            self._wait_until(end)
            yield carry, end

    def _empty_until(self, last_end: int, until: int) -> Iterator[tuple[np.ndarray, int]]:
        """Empty packets for the timesteps without events (the clock goes on)."""
        for end in range(last_end + self.packet_us, until + 1, self.packet_us):
            self._wait_until(end)
            yield np.empty(0, EVENT_DTYPE), end


class CameraSource:
    """A camera through faery (``events_stream_from_camera``); one line when there is none."""

    def __init__(self, intrinsics=None, packet_us: int = 1000, opener: Callable | None = None):
        try:
            import faery
        except ImportError:
            raise TofnetError('camera: faery is not installed (pip install "tofnet[formats]")') from None
        try:
            self.stream = (opener or faery.events_stream_from_camera)()
        except Exception as err:  # noqa: BLE001 - the drivers raise anything; the user needs one line
            detail = " ".join(str(a) for a in getattr(err, "args", ()) if a) or type(err).__name__
            raise TofnetError(f"camera: no event camera found through faery ({' '.join(detail.split())[:200]})") \
                from None
        self.sensor_size = tuple(int(v) for v in self.stream.dimensions())
        self.intrinsics, self.packet_us, self.t0_us = intrinsics, int(packet_us), None
        self._offset_us: float | None = None  # camera time minus this computer's clock (µs)

    def metadata(self) -> Recording:
        return Recording(events=np.empty(0, EVENT_DTYPE), intrinsics=self.intrinsics, sensor_size=self.sensor_size,
                         source="camera")

    def now_us(self) -> float:
        return float("-inf") if self._offset_us is None else time.perf_counter() * 1e6 + self._offset_us

    def packets(self) -> Iterator[tuple[np.ndarray, int]]:
        carry, start = np.empty(0, EVENT_DTYPE), None
        for raw in self.stream:
            if raw is None or not len(raw):
                continue
            events = np.empty(len(raw), EVENT_DTYPE)
            events["t"], events["x"], events["y"] = raw["t"], raw["x"], raw["y"]
            events["p"] = raw["on"] if "on" in raw.dtype.names else raw["p"]
            if self._offset_us is None:  # the camera's latest event is "now"
                self._offset_us = float(events["t"][-1]) - time.perf_counter() * 1e6
                start = int(events["t"][0])
            events = np.concatenate([carry, events]) if len(carry) else events
            cuts, ends = packet_bounds(events["t"], start, self.packet_us)
            for i in range(len(ends) - 1):  # the last timestep may still receive events
                yield events[cuts[i]:cuts[i + 1]], int(ends[i])
            carry = events[cuts[-2]:]


def live_camera(metadata: Recording) -> dict:
    """What a live session is told of the camera: the source's metadata (``Session(camera=...)``), so its
    processes bind to its intrinsics, poses and IMU as a run's do (given only the intrinsics and poses, a
    network whose gyroscope the IMU drives could not start)."""
    return {"camera": metadata}


def warm_up(compiled, metadata: Recording, backend, backend_options) -> None:
    """Compile (or load from numba's cache) the kernels a session runs, before the source's clock starts:
    a throwaway session on 20 ms of a texture sliding across the sensor, so that every path a real
    packet takes (filtering, timing, emitting depth) is compiled, not only the first one."""
    from tofnet.session import Session
    from tofnet.testing import moving_pattern

    width, height = metadata.sensor_size or (2, 2)
    events = moving_pattern((width, height), (300.0, 200.0), 20_000, sample_us=500)
    cuts, ends = packet_bounds(events["t"], 0, 1000)
    with Session(compiled, backend=backend, backend_options=backend_options, t0_us=0, fuse=True,
                 **live_camera(metadata)) as session:
        for i, end in enumerate(ends):  # 1 ms packets, as the run feeds them, then empty ones
            session.feed(events[cuts[i]:cuts[i + 1]], until_us=int(end))
        for end in range(int(ends[-1]) + 1000, int(ends[-1]) + 4000, 1000):
            session.feed(events[:0], until_us=end)
        session.finish()


#: Events fed at once at most while a run catches up (``catching_up``).
CATCH_UP_EVENTS = 1 << 18

#: How far behind (µs) a packet is fed before ``drop_when_late`` drops its events: above the stalls of runs
#: that keep up on average (the replay decoding 65,536 events at once, the garbage collector, a loaded
#: machine's scheduler: up to 47 ms behind on the real EVT3 at 1x using 20 % of a core; docs/live.md).
LATE_TOLERANCE_US = 100_000


def _counted(source: LiveSource, stats: "LiveStats", events: np.ndarray, until_us: int, drop_when_late: bool,
             late_tolerance_us: float = LATE_TOLERANCE_US) -> tuple[np.ndarray, bool]:
    """Count a packet (late: fed more than one packet after it was complete); its events (none when it is
    dropped: ``drop_when_late`` and fed more than ``late_tolerance_us`` after it was complete) and whether
    it was late."""
    behind = source.now_us() - until_us
    stats.packets += 1
    stats.behind_us = max(behind, 0.0)
    stats.max_behind_us = max(stats.max_behind_us, stats.behind_us)
    late = behind > source.packet_us
    stats.late_packets += late
    if drop_when_late and behind > late_tolerance_us and len(events):
        stats.dropped_events += len(events)
        stats.dropped_packets += 1
        events = events[:0]
    return events, late


def catching_up(source: LiveSource, stats: "LiveStats", drop_when_late: bool, batch: Callable[[], bool],
                late_tolerance_us: float = LATE_TOLERANCE_US) -> Iterator[tuple[np.ndarray, int]]:
    """The source's packets, counted; while the run is behind (a packet late, not dropped) and ``batch()``
    says so (the session runs bands of rows in threads, which pay on large packets only), the packets already
    complete after it come with it as one (up to ``CATCH_UP_EVENTS`` events): the same events and promises,
    so a run that fell behind catches up on several cores (docs/live.md, "Fast sensors")."""
    packets = source.packets()
    for events, until_us in packets:
        events, late = _counted(source, stats, events, until_us, drop_when_late, late_tolerance_us)
        if not late or drop_when_late or not batch():
            yield events, until_us
            continue
        parts, total = [events], len(events)
        while total < CATCH_UP_EVENTS and source.now_us() >= until_us + source.packet_us:
            following = next(packets, None)  # complete already: no wait
            if following is None:
                break
            more, until_us = following[0], following[1]
            more, _ = _counted(source, stats, more, until_us, drop_when_late, late_tolerance_us)
            parts.append(more)
            total += len(more)
        stats.batches += len(parts) > 1
        yield (np.concatenate(parts) if len(parts) > 1 else events), until_us


@contextlib.contextmanager
def _ctrl_c_stops(stats: LiveStats) -> Iterator[None]:
    """Ctrl-C (SIGINT) ends the run as ``stop()`` does, after the packet being fed: ``stats.interrupted`` is set
    and the session finishes, so the figures of the run up to it are whole. A second Ctrl-C raises
    ``KeyboardInterrupt`` as usual. Only in the main thread, and only over Python's own handler."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return

    def interrupted(signum, frame) -> None:
        stats.interrupted = True
        signal.signal(signal.SIGINT, signal.default_int_handler)

    signal.signal(signal.SIGINT, interrupted)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _until_interrupted(packets: Iterator, stats: LiveStats) -> Iterator:
    """``packets`` until Ctrl-C (``stats.interrupted``), or a ``KeyboardInterrupt`` raised while waiting for the
    next one (a second Ctrl-C while a camera sends nothing), which marks it: between two packets the session
    can finish."""
    while not stats.interrupted:
        try:
            item = next(packets)
        except StopIteration:
            return
        except KeyboardInterrupt:
            stats.interrupted = True
            return
        yield item


def run_live(source: LiveSource, network, *, backend: str = "fixed", backend_options: dict | None = None,
             compile_options: dict | None = None, drop_when_late: bool = False,
             late_tolerance_us: float = LATE_TOLERANCE_US, on_depth: Callable[[np.ndarray], None] | None = None,
             tick: Callable[[], None] | None = None,
             stop: Callable[[], bool] | None = None) -> tuple[LiveStats, object]:
    """Run ``network`` on ``source`` until it ends (or ``stop()`` is true, or Ctrl-C: ``_ctrl_c_stops``); the
    statistics and the run's ``RunResult`` (counts, latency; its outputs only those of the last steps, run at
    the end: the estimates are not kept). ``on_depth(records)`` sees every batch of depth estimates as it
    comes (the last steps' too); ``tick()`` is called after every packet (to refresh a display).
    ``drop_when_late``: drop (and count) the events of a packet fed more than ``late_tolerance_us`` after it
    was complete."""
    if not (isinstance(late_tolerance_us, (int, float)) and 0 <= late_tolerance_us < np.inf):
        raise TofnetError(f"late_tolerance_us: expected a number of µs >= 0, got {late_tolerance_us!r}")
    from tofnet.compiler import compile_network
    from tofnet.session import Session

    compiled = compile_network(network, **(compile_options or {}))
    camera = live_camera(source.metadata())
    warm_up(compiled, source.metadata(), backend, backend_options)
    stats, session, wall0, cpu0 = LiveStats(), None, time.perf_counter(), time.process_time()
    stats.late_tolerance_us = late_tolerance_us if drop_when_late else None
    stats.speed = float(getattr(source, "speed", 1.0))  # a replay's; a camera runs at its own
    primary, step_us, latency = None, source.packet_us, 0
    first = None

    def open_session(t0_us: int):
        nonlocal session, primary, step_us, latency, first
        first = t0_us
        session = Session(compiled, backend=backend, backend_options=backend_options, t0_us=t0_us,
                          keep_outputs=False, fuse=True, **camera)  # on_depth sees them; memory stays flat for hours
        primary, step_us = session.stream.primary, session.timestep_us
        latency = session.output_latency(primary) if primary else 0

    try:
        if source.t0_us is not None:  # before the source's clock starts: opening takes time
            open_session(source.t0_us)
        def runs_bands() -> bool:  # a graph stream's bands (a fused stream keeps 1 ms packets whole: faster)
            return session is not None and len(getattr(session.stream, "extra", {}).get("bands", ())) > 1

        with _ctrl_c_stops(stats):
            packets = catching_up(source, stats, drop_when_late, runs_bands, late_tolerance_us)
            packets = _until_interrupted(packets, stats)
            for events, until_us in packets:
                if session is None:
                    if not len(events):
                        continue
                    open_session(int(events["t"][0]))
                stats.events_in += len(events)
                produced = session.feed(events, until_us)
                depth = produced.get(primary) if primary else None
                if depth is not None and len(depth):
                    now = source.now_us()
                    stats.delays.add(now - (depth["t"] - (latency + 1) * step_us))
                    stats.depth_out += len(depth)
                    if on_depth is not None:
                        on_depth(depth)
                stats.span_us = until_us - first
                if tick is not None:
                    tick()
                if stop is not None and stop():
                    break
        if session is None:
            raise TofnetError("live: the source gave no events" + (" before Ctrl-C" if stats.interrupted else ""))
        result = session.finish()  # the steps still in flight (not counted in the delays: nothing waits for them)
        if primary and primary in result.outputs:
            stats.depth_out += len(result.outputs[primary])
        for name in result.depth_outputs if on_depth is not None else ():
            if len(result.outputs[name]):
                on_depth(result.outputs[name])
    finally:
        if session is not None:
            session.stop()
        stats.wall_s, stats.cpu_s = time.perf_counter() - wall0, time.process_time() - cpu0
    return stats, result
