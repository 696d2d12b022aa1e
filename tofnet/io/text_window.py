"""A time window of an ``events.txt`` without parsing the whole file: a binary search on byte offsets.

The file is memory-mapped. A probe at a byte offset moves to the next line start and
parses the first data line there with the same compiled parser as ``read_events_txt``
(so its time is the exact µs the full read gives). The search keeps two line starts:
every data line before ``lo`` is earlier than the bound, every one from ``hi`` on is at
or after it; it stops when they are within ``REGION`` bytes. Then only the bytes from the
start bound's ``lo`` to the stop bound's ``hi`` are parsed, and cut exactly by time.

Whatever it meets that the full reader would refuse (a bad line, a time going back
inside the region) makes it read the whole file instead, so that the error names its
line as always; lines outside the window are otherwise not checked.
"""

from __future__ import annotations

import mmap
from pathlib import Path

import numpy as np

from tofnet.io.files import open_regular

#: Bytes left to parse around each bound when the search stops.
REGION = 1 << 20


class _Fallback(Exception):
    """Something the full reader should report (with its line number)."""


def read_text_window(path: str | Path, window, notes: list[str]) -> tuple[np.ndarray, int, int]:
    """``(events in window, first event µs, last event µs)`` of ``events.txt`` at ``path``."""
    from tofnet.io.events import read_events_txt

    path = Path(path)
    with open_regular(path, "events file") as handle:
        size = handle.seek(0, 2)
        if size == 0:
            return read_events_txt(path, notes), 0, 0  # the reader's message for an empty file
        mapped = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            buf = np.frombuffer(mapped, dtype=np.uint8)
            try:
                return _window(buf, window, notes, path)
            except _Fallback:
                pass
            finally:
                del buf
        finally:
            _close(mapped)
    events = read_events_txt(path, notes)
    first, last = int(events["t"][0]), int(events["t"][-1])
    start, stop = window.resolve(first)
    t = events["t"]
    lo = int(np.searchsorted(t, start))
    hi = len(t) if stop is None else max(int(np.searchsorted(t, stop)), lo)
    return events[lo:hi], first, last


def _close(mapped: mmap.mmap) -> None:
    """Unmap now, or when the last view of the map dies: a view can outlive the read in a frame
    someone else holds (Dask's profiler samples the running task's frames, for one)."""
    try:
        mapped.close()
    except BufferError:
        pass


def _window(buf: np.ndarray, window, notes: list[str], path: Path) -> tuple[np.ndarray, int, int]:
    size = len(buf)
    first = _data_line(buf, 0, size)
    last = _last_time(buf)
    if first is None or last is None:
        raise _Fallback  # no events: the reader says so
    start, stop = window.resolve(first[2])
    lo = _bound(buf, start)[0]
    hi = size if stop is None else _bound(buf, stop)[1]
    from tofnet.io.events import ROUNDED_NOTE, parse_lines

    events, info = parse_lines(np.ascontiguousarray(buf[lo:hi]))
    if info[0] != 0:
        raise _Fallback
    t = events["t"]
    keep = events[int(np.searchsorted(t, start)):len(t) if stop is None else int(np.searchsorted(t, stop))]
    if info[8]:
        notes.append(ROUNDED_NOTE.format(name=path.name, count=int(info[8])) + " (in the bytes read for the window)")
    return keep, first[2], last


def _bound(buf: np.ndarray, value: int) -> tuple[int, int]:
    """Line starts ``(lo, hi)``: every data line before ``lo`` is earlier than ``value`` µs, every
    one from ``hi`` on is at or after it, and ``hi - lo <= REGION`` (or no probe can split them)."""
    lo, hi = 0, len(buf)
    while hi - lo > REGION:
        mid = (lo + hi) // 2
        probe = _next_line(buf, mid)
        if probe >= hi:  # one line spans [mid, hi): nothing to split there
            break
        line = _data_line(buf, probe, hi)
        if line is None:
            hi = probe  # no data line in [probe, hi): the bound is before
            continue
        line_start, line_end, t = line
        if t >= value:
            hi = line_start
        else:
            lo = line_end
    return lo, hi


def _next_line(buf: np.ndarray, at: int) -> int:
    """The first line start at or after ``at``."""
    if at <= 0:
        return 0
    found = np.flatnonzero(buf[at - 1:at - 1 + REGION] == 10)
    while found.size == 0:  # a very long line: look further
        at += REGION
        if at - 1 >= len(buf):
            return len(buf)
        found = np.flatnonzero(buf[at - 1:at - 1 + REGION] == 10)
    return at - 1 + int(found[0]) + 1


def _data_line(buf: np.ndarray, at: int, end: int) -> tuple[int, int, int] | None:
    """``(start, end, t µs)`` of the first data line starting in ``[at, end)``, or None."""
    from tofnet.io.events import parse_lines

    while at < end:
        stop = _next_line(buf, at + 1)
        line = np.ascontiguousarray(buf[at:stop])
        events, info = parse_lines(line, 2)
        if info[0] != 0:
            raise _Fallback
        if len(events):
            return at, stop, int(events["t"][0])
        at = stop
    return None


def _last_time(buf: np.ndarray) -> int | None:
    """The time of the file's last data line."""
    from tofnet.io.events import parse_lines

    end = len(buf)
    while end > 0:
        begin = _next_line(buf, end - REGION) if end > REGION else 0
        if begin >= end:  # a last line longer than REGION
            raise _Fallback
        events, info = parse_lines(np.ascontiguousarray(buf[begin:end]))
        if info[0] != 0:
            raise _Fallback
        if len(events):
            return int(events["t"][-1])
        end = begin
    return None
