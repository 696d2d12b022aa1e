"""Time windows of a recording: ``--start 12.5s --duration 2s`` (or ``--until``), parsed once.

A time is seconds from the recording's first event (``12.5s``, ``500ms``, ``12.5``) or,
with ``@``, absolute on the file's clock (``@1627000012.5s``). Text is converted to
integer microseconds exactly (decimal arithmetic, halves away from zero, as
``events.txt``). ``TimeWindow.resolve(first_us)`` gives the half-open interval
``[start, stop)`` in the file's µs; the readers (``EventSource.set_window``) apply it,
so every command and batch task windows the same way.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from decimal import ROUND_HALF_UP, Decimal, InvalidOperation

import numpy as np

from tofnet.errors import TofnetError, quote
from tofnet.events import MAX_TIME_US

_UNITS = {"s": Decimal(1_000_000), "ms": Decimal(1000), "us": Decimal(1), "µs": Decimal(1)}
_TIME = re.compile(r"^\s*(@?)\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zµ]*)\s*$")


@dataclass(frozen=True)
class TimePoint:
    """A time in µs: from the recording's first event, or ``absolute`` on the file's clock."""

    us: int
    absolute: bool = False

    def text(self) -> str:
        return absolute_text(self.us) if self.absolute else seconds_text(self.us)


def seconds_text(us: int) -> str:
    """``0.00002 s``, ``12.5 s``: µs as seconds, exact and without an exponent."""
    return f"{Decimal(int(us)).scaleb(-6).normalize():f} s"


def absolute_text(us: int) -> str:
    """``@1589163147.368868 s``: a time on the file's clock as ``@`` times are written, exact to the µs."""
    return f"@{Decimal(int(us)).scaleb(-6):f} s"


def parse_time(value: object, what: str, *, absolute_allowed: bool = True) -> TimePoint:
    """``12.5s``, ``500ms``, ``250us``, ``12.5`` (seconds) or ``@1627000012.5s`` as a ``TimePoint``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise TofnetError(f"{what}: expected a time like 12.5s, 500ms or @1627000012.5s, got {quote(value)}")
    match = _TIME.match(str(value)) if len(str(value)) <= 100 else None
    if match is None or (match.group(3) or "s") not in _UNITS or (match.group(1) and not absolute_allowed):
        hint = "12.5s or 500ms" + (" (from the first event) or @1627000012.5s (absolute)" if absolute_allowed else "")
        raise TofnetError(f"{what}: expected a time like {hint}, got {quote(value)}")
    try:
        us = (Decimal(match.group(2)) * _UNITS[match.group(3) or "s"]).to_integral_value(ROUND_HALF_UP)
    except InvalidOperation:
        raise TofnetError(f"{what}: expected a finite time, got {quote(value)}") from None
    if not abs(us) < MAX_TIME_US:
        raise TofnetError(f"{what}: {quote(value)} is out of the time range (|t| < 2**61 µs)")
    return TimePoint(int(us), bool(match.group(1)))


@dataclass(frozen=True)
class TimeWindow:
    """``[start, start + duration)`` or ``[start, until)``; a missing start is the first event."""

    start: TimePoint | None = None
    duration_us: int | None = None
    until: TimePoint | None = None

    def resolve(self, first_us: int) -> tuple[int, int | None]:
        """``(start, stop)`` µs on the file's clock, ``stop`` ``None`` for "to the end"."""
        def at(point: TimePoint) -> int:
            return point.us if point.absolute else first_us + point.us
        start = at(self.start) if self.start is not None else first_us
        stop = start + self.duration_us if self.duration_us is not None else \
            at(self.until) if self.until is not None else None
        return start, stop

    def text(self) -> str:
        """How the window was asked for, for notes and messages."""
        parts = [f"start {self.start.text()}" if self.start else "from the first event"]
        if self.duration_us is not None:
            parts.append(f"duration {seconds_text(self.duration_us)}")
        if self.until is not None:
            parts.append(f"until {self.until.text()}")
        return ", ".join(parts)

    @property
    def absolute(self) -> bool:
        """Whether an end was given on the file's clock (``@``): messages then say absolute times."""
        return any(point is not None and point.absolute for point in (self.start, self.until))


def parse_window(start: object = None, duration: object = None, until: object = None,
                 names: tuple[str, str, str] = ("--start", "--duration", "--until")) -> TimeWindow | None:
    """The window the three options describe (``None`` when none is given); ``TofnetError`` naming the option."""
    if start is None and duration is None and until is None:
        return None
    if duration is not None and until is not None:
        raise TofnetError(f"{names[1]} and {names[2]}: give one of them, not both")
    begin = _not_before_first(parse_time(start, names[0]), names[0]) if start is not None else None
    length = None
    if duration is not None:
        length = parse_time(duration, names[1], absolute_allowed=False).us
        if length <= 0:
            raise TofnetError(f"{names[1]}: expected a positive duration, got {quote(duration)}")
    end = _not_before_first(parse_time(until, names[2]), names[2]) if until is not None else None
    if begin is not None and end is not None and begin.absolute == end.absolute and end.us <= begin.us:
        raise TofnetError(f"{names[2]}: {end.text()} is not after {names[0]} {begin.text()}")
    return TimeWindow(begin, length, end)


def _not_before_first(point: TimePoint, what: str) -> TimePoint:
    """A time from the first event must not be negative (nothing is before it); absolute ones may be."""
    if not point.absolute and point.us < 0:
        raise TofnetError(f"{what}: {point.text()} is before the first event; expected 0 or more (seconds from "
                          "the first event), or @T for a time on the file's clock")
    return point


def rows_in(times_s: np.ndarray, start_us: int, stop_us: int | None) -> slice:
    """The rows of sorted ``times_s`` (seconds) that cover ``[start, stop)``: those inside plus the
    one before and the one after, so that interpolating inside the window gives what it gave before."""
    times_us = np.asarray(times_s, dtype=np.float64) * 1e6
    first = max(int(np.searchsorted(times_us, start_us, side="right")) - 1, 0)
    last = len(times_us) if stop_us is None else min(int(np.searchsorted(times_us, stop_us, side="left")) + 1,
                                                     len(times_us))
    return slice(first, max(last, first))


def window_trajectory(trajectory, start_us: int, stop_us: int | None):
    """``trajectory`` cut to the poses covering the window (velocities inside it unchanged)."""
    from tofnet.io.groundtruth import Trajectory

    if not isinstance(trajectory, Trajectory):
        return trajectory
    keep = rows_in(trajectory.times, start_us, stop_us)
    if keep.stop - keep.start < 2:  # a window beyond the poses: the nearest segment gives the same values
        keep = slice(max(min(keep.start, len(trajectory) - 2), 0), max(min(keep.start, len(trajectory) - 2), 0) + 2)
    if keep == slice(0, len(trajectory)):
        return trajectory
    out = Trajectory(trajectory.times[keep], trajectory.positions[keep], trajectory.quaternions[keep],
                     source=trajectory.source)
    out.quaternions = trajectory.quaternions[keep]  # normalised already: normalising again moves the last bits
    return out


def window_rows(rows: np.ndarray | None, start_us: int, stop_us: int | None) -> np.ndarray | None:
    """IMU rows (``t`` seconds first) covering the window."""
    if rows is None or len(rows) == 0:
        return rows
    return rows[rows_in(rows[:, 0], start_us, stop_us)]


def window_filter(source, packets: Iterable[np.ndarray], start: int,
                  stop: int | None) -> Iterator[np.ndarray]:
    """``packets`` cut to ``[start, stop)`` µs (sorted files): packets wholly before ``start`` are skipped
    (``source._first_index`` counts them), iteration stops at the first packet reaching ``stop``. Once
    inside the window nothing is dropped for being early, so ``chunks`` still sees a time going back."""
    skipped, started = 0, False
    for packet in packets:
        if not len(packet):
            continue
        t = packet[packet.dtype.names[0]]
        first, last = int(t[0]), int(t[-1])
        source._last_seen_us = last
        lo = 0
        if not started:
            if last < start:
                skipped += len(packet)
                source._first_index = skipped
                continue
            lo = int(np.searchsorted(t, start, side="left")) if first < start else 0
            skipped += lo
            source._first_index = skipped
        hi = len(packet)
        if stop is not None and last >= stop:
            hi = lo if stop <= first else max(int(np.searchsorted(t, stop, side="left")), lo)
        if hi > lo:
            started = True
            yield packet[lo:hi]
        if stop is not None and last >= stop:
            return
    source._seen_end = True  # every packet decoded: _last_seen_us is the file's last event


def first_at_or_after(times, n: int, value: int, bracket: tuple[int, int] | None = None) -> int:
    """Index of the first of ``n`` sorted times at or after ``value`` (µs). ``times(lo, hi)`` reads
    times ``lo..hi-1`` as µs; ``bracket`` is a guess from the file's index (``ms_to_idx``), used only
    when the times at its ends confirm it, so a wrong index cannot give wrong events."""
    lo, hi = 0, n
    if bracket is not None:
        a, b = bracket
        if 0 <= a <= b <= n and (a == 0 or times(a - 1, a)[0] < value) and (b == n or times(b, b + 1)[0] >= value):
            lo, hi = a, b
    while hi - lo > 1 << 16:  # bisect on single reads until the rest is one small read
        mid = (lo + hi) // 2
        if times(mid, mid + 1)[0] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo + int(np.searchsorted(times(lo, hi), value, side="left")) if hi > lo else lo
