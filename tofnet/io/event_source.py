"""The base of every reader: ``EventSource``, an open recording's metadata and its events in
time-ordered chunks of bounded size (``tofnet.io.source`` opens one for any format).

The checks of docs/reliability.md are made here once for every format (``check_metadata`` when
a file is opened and after ``read()``, ``check_packet`` on every packet a reader returns), and
errors of the decoding libraries become one-line ``DataError``s. Readers subclass it; the
registry that picks a reader by content (``tofnet.io.source``) sits above them all.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np
from numba import njit

import tofnet.numba_cache  # noqa: F401 - before any cached kernel: numba picks its cache key at decoration
from tofnet.errors import DataError, located, reason
from tofnet.events import EVENT_DTYPE, sensor_size_problem
from tofnet.io.checks import check_metadata, check_packet, is_decode_error
from tofnet.io.recording import Intrinsics, Recording, VelocitySource

#: Events per chunk unless asked otherwise: 13 MB of ``EVENT_DTYPE``.
DEFAULT_CHUNK = 1_000_000
#: Events whose times ``first_times`` keeps (a first packet: the plausibility notes look at them).
FIRST_TIMES = 1 << 16

#: ``progress(events_done, events_total)``; the total is ``None`` when the file does not say.
ProgressHook = Callable[[int, "int | None"], None]


class EventSource:
    """Base of every reader: metadata as attributes, events through ``chunks``.

    Subclasses set the attributes in ``__init__`` and implement ``_packets`` (and
    ``_depth`` when the file holds ground-truth depth).
    """

    format = "?"

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.detail = ""  # e.g. "EVT3", "DSEC layout"
        self.sensor_size: tuple[int, int] | None = None
        self.intrinsics: Intrinsics | None = None
        self.trajectory: VelocitySource | None = None
        self.imu: np.ndarray | None = None  # (n, 7): t s, accel m/s², gyro rad/s
        self.n_events: int | None = None  # known without decoding, else None
        self.has_depth = False
        self.streams: dict[str, str] = {}  # other streams in the file: name -> what
        self.unread: list[str] = []  # those of them tofnet does not read ("name, what"): convert says so
        self.notes: list[str] = []
        self._first_times: np.ndarray | None = None  # the first packet's times (first_times)
        #: A sensor the events may fill beyond the file's stated size (open_recording's ``reading_size``), px.
        self.reading_size: tuple[int, int] | None = None
        self.doubts: list[tuple[str, str]] = []  # (topic, note) that usually mean a mistake (tofnet.io.plausible)
        self.window: tuple[int, int | None] | None = None  # [start, stop) µs on the file's clock (set_window)
        self._origin_us = 0  # the file's first event, which relative window times count from
        self._first_index = 0  # file index of the first event in the window (for _depth)
        self._last_seen_us: int | None = None  # latest time decoded, for "the window is past the end"
        self._seen_end = False  # decoding went to the file's end: _last_seen_us is its last event
        self._asked = None  # the TimeWindow as asked (set_window), for messages in the user's terms
        self.frame_gt = None  # ground truth as frames (tofnet.io.frames.FrameDepth): dataset sequences
        self.remap = None  # moves each packet's pixels (tofnet.io.sequences.PixelRemap: DSEC --rectify)
        self._remap_noted: str | None = None  # the remap's note as it stands in ``notes`` (_note_remap)

    # --- to implement -------------------------------------------------------------
    def _packets(self, size_hint: int) -> Iterable[np.ndarray]:
        """Event arrays in file order: ``EVENT_DTYPE`` or any dtype with fields t, x, y, p in that order."""
        raise NotImplementedError

    def _depth(self, events: np.ndarray, first_index: int) -> np.ndarray | None:
        """True depth (m, NaN unknown) of ``events``, which start at event ``first_index`` of the file."""
        return None if self.frame_gt is None else self.frame_gt.at_events(events)

    def first_time(self) -> int | None:
        """The file's first event time (µs), ``None`` without events. Readers with an index override
        this; the default decodes the first packet (once: ``first_times``)."""
        times = self.first_times()
        return int(times[0]) if len(times) else None

    def first_times(self, count: int = FIRST_TIMES) -> np.ndarray:
        """The times (µs, int64) of the file's first events: its first packet's, at most ``count`` (at most
        ``FIRST_TIMES``; decoded once per source)."""
        if self._first_times is None:
            packets = iter(self._packets(FIRST_TIMES))
            self._first_times = np.empty(0, np.int64)
            try:
                for packet in packets:
                    if len(packet):
                        self._first_times = np.array(packet[packet.dtype.names[0]][:FIRST_TIMES], dtype=np.int64)
                        break
            finally:
                getattr(packets, "close", lambda: None)()
        return self._first_times[:count]

    def _window_packets(self, size_hint: int, start: int, stop: int | None) -> Iterable[np.ndarray]:
        """The events of ``[start, stop)``. The default decodes from the beginning, skips whole packets
        before ``start`` uncopied and stops at the first packet past ``stop``; readers with an index
        (HDF5) override it to read only the window's rows."""
        from tofnet.io.window import window_filter
        yield from window_filter(self, self._packets(size_hint), start, stop)

    def _window_end_us(self) -> int | None:
        """The file's last event time when it is cheap to know (else what decoding saw)."""
        return self._last_seen_us

    def last_time(self) -> int | None:
        """The file's last event time (µs), for messages; ``None`` when the file cannot say. Readers that
        know it cheaply override this; the default is what decoding saw when it went to the end, else the
        rest of the file is decoded for it (only a window without events asks: an error follows)."""
        if not self._seen_end:
            packets = iter(self._packets(DEFAULT_CHUNK))
            try:
                for packet in packets:
                    if len(packet):
                        self._last_seen_us = int(packet[packet.dtype.names[0]][-1])
            except BaseException as err:
                if not isinstance(err, DataError) and not is_decode_error(err, self.format):
                    raise
                return None  # a file that cannot be decoded to its end: its end is not said
            finally:
                getattr(packets, "close", lambda: None)()
            self._seen_end = True
        return self._last_seen_us

    # --- time windows -------------------------------------------------------------
    def set_window(self, window) -> None:
        """Read only the events of ``window`` (a ``tofnet.io.window.TimeWindow``); poses and IMU are
        cut to the samples covering it. Relative times count from the file's first event."""
        from tofnet.io.window import window_rows, window_trajectory

        first = self.first_time()
        if first is None:
            raise DataError(located(self.path, None, "no events"))
        start, stop = window.resolve(first)
        self.window, self._origin_us, self._asked = (start, stop), first, window
        self.trajectory = window_trajectory(self.trajectory, start, stop)
        self.imu = window_rows(self.imu, start, stop)
        self.n_events = self._window_count(start, stop)
        self.notes.append(f"time window {self.window_text()} ({window.text()})")

    def _window_count(self, start: int, stop: int | None) -> int | None:
        """Events in the window when the file's index says so without decoding."""
        return None

    def window_text(self) -> str:
        """``12.5 s .. 14.5 s from the first event`` (``from 20 s after the first event to the end``)."""
        from tofnet.io.window import seconds_text

        start, stop = self.window
        if stop is None:
            return f"from {seconds_text(start - self._origin_us)} after the first event to the end"
        return f"{seconds_text(start - self._origin_us)} .. {seconds_text(stop - self._origin_us)} from the first event"

    def empty_window(self) -> DataError:
        """The one-line error for a window without events: the window in the terms it was asked in
        (absolute ``@`` times when an end was given so) and where the recording's events lie."""
        from tofnet.io.window import absolute_text

        start, stop = self.window
        first, last = self._origin_us, self.last_time()
        if self._asked is not None and self._asked.absolute:
            asked = f"{absolute_text(start)} .. {'the end' if stop is None else absolute_text(stop)}"
            span = f"the recording's first event is at {absolute_text(first)}" if last is None else \
                f"the recording's events span {absolute_text(first)} .. {absolute_text(last)} ({(last - first) * 1e-6:g} s)"
        else:
            asked = self.window_text()
            span = "" if last is None else f"the recording ends {(last - first) * 1e-6:g} s after its first event"
        return DataError(located(self.path, None, f"no events in the time window {asked}" + (span and f"; {span}")))

    # --- the interface ------------------------------------------------------------
    def chunks(self, n_events: int = DEFAULT_CHUNK, progress: ProgressHook | None = None) -> Iterator[np.ndarray]:
        """``EVENT_DTYPE`` arrays of ``n_events`` events (the last shorter), in time order.

        Each array is new (the caller may keep it). Raises ``DataError`` naming the
        event index when a timestamp is earlier than the one before it.
        """
        if n_events < 1:
            raise ValueError(f"n_events must be positive, got {n_events}")
        done = 0
        previous = None
        size = min(n_events, self.n_events) if self.n_events else n_events
        for chunk, back in _rechunk(self._checked_packets(size), size):
            if back >= 0:
                before = int(chunk["t"][back - 1]) if back > 0 else previous
                raise DataError(located(self.path, None, f"event {done + back + 1}: time goes back "
                                                         f"({int(chunk['t'][back])} µs after {before} µs); "
                                                         "events must be sorted by time"))
            previous = int(chunk["t"][-1])
            done += len(chunk)
            if progress is not None:
                progress(done, self.n_events)
            yield chunk
        if done == 0 and self.window is not None:
            raise self.empty_window()

    def _checked_packets(self, size_hint: int) -> Iterator[np.ndarray]:
        """``_packets``, each checked by ``check_packet``; decoding libraries' errors as ``DataError``."""
        packets = iter(self._packets(size_hint) if self.window is None
                       else self._window_packets(size_hint, *self.window))
        done = 0
        if self.remap is not None:  # each read counts its own drops (tofnet live reads the start, then all)
            self.remap.dropped = 0
            self._note_remap()
        while True:
            try:
                packet = next(packets)
            except StopIteration:
                return
            except BaseException as err:
                if not is_decode_error(err, self.format):
                    raise
                raise DataError(located(self.path, None, f"cannot decode the events after event {done:,}: "
                                                         f"{reason(err)}")) from None
            check_packet(packet, done, self.path)
            done += len(packet)
            if self.remap is not None:
                packet = self.remap(packet)
                self._note_remap()
            yield packet

    def _note_remap(self) -> None:
        """The remap's count of events left out, in ``notes`` as it stands: updated with every packet, so
        that every way of reading (``read``, ``chunks`` in run, info, live, even a read stopped early)
        shows it, and ``metadata()``'s notes (the same list) too."""
        note = self.remap.note()
        if self._remap_noted in self.notes:
            self.notes[self.notes.index(self._remap_noted)] = note
        else:
            self.notes.append(note)
        self._remap_noted = note

    def metadata(self, *, imu: bool = True) -> Recording:
        """What is known about the camera before reading the events: a ``Recording`` without
        events (for streams, which read them in chunks). ``imu`` False: a reader may leave out an
        IMU it would have to decode the file for (AEDAT4)."""
        return Recording(events=np.empty(0, EVENT_DTYPE), intrinsics=self.intrinsics, trajectory=self.trajectory,
                         sensor_size=self.sensor_size, imu=self.imu, source=str(self.path), notes=self.notes,
                         frame_gt=self.frame_gt)

    def read(self, progress: ProgressHook | None = None) -> Recording:
        """All events and metadata as a ``Recording``; ``DataError`` when there are no events."""
        parts, depths = [], []
        done = 0
        for chunk in self.chunks(DEFAULT_CHUNK, progress):
            parts.append(chunk)
            if self.has_depth:
                depths.append(self._depth(chunk, self._first_index + done))
            done += len(chunk)
        if not parts:
            raise DataError(located(self.path, None, "no events"))
        events = parts[0] if len(parts) == 1 else np.concatenate(parts)
        del parts
        recording = Recording(events=events, intrinsics=self.intrinsics, trajectory=self.trajectory,
                              sensor_size=self.sensor_size, imu=self.imu, source=str(self.path),
                              notes=list(self.notes),
                              frame_gt=self.frame_gt)
        if depths:
            recording.gt_depth = np.concatenate(depths)
        if recording.sensor_size is None:
            extent = (int(events["x"].max()) + 1, int(events["y"].max()) + 1)
            problem = sensor_size_problem(*extent)
            if problem:
                raise DataError(located(self.path, None, f"sensor size not in the file, and the events' extent "
                                                         f"is not a usable one: {problem}"))
            recording.sensor_size = extent
            recording.notes.append(f"sensor size not in the file: {extent[0]}x{extent[1]} taken from the events' "
                                   "extent (pass --sensor-size to set it)")
        check_metadata(recording, self.path)  # some readers find metadata (AEDAT4's IMU) among the events
        return recording

    def not_read(self, name: str, what: str = "not read") -> None:
        """A stream of the file tofnet does not read: shown by ``tofnet info``, said by ``tofnet convert``."""
        self.streams[name] = what
        self.unread.append(name if what == "not read" else f"{name}, {what}")

    def describe(self) -> str:
        """``format (detail)`` for messages and ``tofnet info``."""
        return f"{self.format} ({self.detail})" if self.detail else self.format

    def close(self) -> None:
        """Release the file (readers that keep one open override this)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()



def _rechunk(packets: Iterable[np.ndarray], n: int) -> Iterator[tuple[np.ndarray, int]]:
    """Re-cut arrays of any sizes into new ``EVENT_DTYPE`` arrays of ``n`` (the last shorter).

    Yields ``(chunk, back)``: ``back`` is the index in the chunk of the first event
    stamped earlier than the one before it (across packets and chunks too), or -1. Each
    event is copied once, in a compiled loop that also checks the order.
    """
    # at least two records, so that the fields are strided views whatever n (a buffer of one record has
    # contiguous fields: another compiled signature of _copy_checked); only n of them are filled
    width = max(n, 2)
    buffer = np.empty(width, dtype=EVENT_DTYPE)
    fill, back = 0, -1
    last_t = np.zeros(1, dtype=np.int64)
    started = np.zeros(1, dtype=np.bool_)
    for packet in packets:
        columns, size = _columns(packet), len(packet)
        start = 0
        while start < size:
            take = min(n - fill, size - start)
            first_back = _copy_checked(buffer["t"], buffer["x"], buffer["y"], buffer["p"], fill, *columns,
                                       start, take, last_t, started)
            if back < 0 and first_back >= 0:
                back = fill + first_back
            fill += take
            start += take
            if fill == n:
                yield buffer[:n], back
                buffer = np.empty(width, dtype=EVENT_DTYPE)
                fill, back = 0, -1
    if fill:
        # A copy only when most of the buffer is empty (a fresh copy costs page faults too).
        yield (buffer[:fill] if 2 * fill >= n else buffer[:fill].copy()), back


#: The column kinds ``_copy_checked`` is compiled for (``EVENT_DTYPE``'s: t, x, y, p).
_KINDS = tuple(EVENT_DTYPE[name] for name in ("t", "x", "y", "p"))


def _columns(packet: np.ndarray) -> list[np.ndarray]:
    """The t, x, y, p fields of ``packet`` as ``_copy_checked`` reads them, of one kind whatever the reader,
    so that one compiled signature serves every format (``tofnet warmup`` compiles it on ECD's chunks):
    a field of the same size as ``EVENT_DTYPE``'s (faery's uint64 t, bool polarity) is viewed as it, which
    ``_copy_checked`` copies to the same values; and always strided views, as a packet of two or more records
    gives (numba types the fields of a one-record packet as contiguous, another signature), by copying a
    one-record packet into two records (the kernel copies ``count`` of them); and read-only views, as a
    memory-mapped file's are (numba types read-only arrays apart too)."""
    if len(packet) == 1:
        packet = np.concatenate([packet, packet])
    columns = []
    for name, kind in zip(packet.dtype.names[:4], _KINDS):
        column = packet[name]
        if (column.dtype != kind and column.dtype.kind in "biu" and column.dtype.isnative
                and column.dtype.itemsize == kind.itemsize):
            column = column.view(kind)
        else:
            column = column.view()
        column.flags.writeable = False  # read-only, as some readers' packets are (memory-mapped files)
        columns.append(column)
    return columns


@njit(cache=True)
def _copy_checked(out_t, out_x, out_y, out_p, at, t, x, y, p, start, count, last_t, started):
    """Copy ``count`` events from ``start`` into the chunk fields at ``at``; first time going back or -1."""
    for i in range(count):
        out_t[at + i] = t[start + i]
        out_x[at + i] = x[start + i]
        out_y[at + i] = y[start + i]
        out_p[at + i] = 1 if p[start + i] else 0
    first_back = -1
    if count > 0:
        if started[0] and out_t[at] < last_t[0]:
            first_back = 0
        else:
            for i in range(1, count):
                if out_t[at + i] < out_t[at + i - 1]:
                    first_back = i
                    break
        last_t[0] = out_t[at + count - 1]
        started[0] = True
    return first_back
