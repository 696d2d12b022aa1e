"""Event files: ECD ``events.txt`` (numpy ``.npy``/``.npz`` in ``tofnet.io.arrays``), read into ``EVENT_DTYPE``.

The text reader parses the raw bytes in one compiled pass (no Python per line) and
converts the decimal seconds to integer microseconds exactly, without going through
a float: ``1468939993.0674165`` s becomes ``1468939993067417`` µs (half away from zero),
whatever the number of digits. How many times had sub-µs digits (and were rounded) is
counted and reported in ``Recording.notes``. Every time must satisfy
``|t| < MAX_TIME_US`` (``tofnet.events``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numba import njit

import tofnet.numba_cache  # noqa: F401 - before any cached kernel: numba picks its cache key at decoration
from tofnet.errors import DataError, located, quote_field
from tofnet.events import EVENT_DTYPE, MAX_TIME_US
from tofnet.io.arrays import COLUMNS as _COLUMNS, MAX_COORD as _MAX_COORD, check_writable
from tofnet.io.arrays import events_from_columns, read_events_npy, write_events_npy  # noqa: F401 (their old home)
from tofnet.io.files import atomic_write, read_bytes

_EXPECTED = "4 columns 't x y p' (seconds, column px, row px, polarity 0/1)"
_POW10 = np.array([10 ** k for k in range(19)], dtype=np.int64)
_I64_MAX = np.iinfo(np.int64).max
_MAX_TIME_US = np.int64(MAX_TIME_US)

# Status codes of the compiled parser.
_OK, _COLUMN_COUNT, _NOT_NUMBER, _NOT_WHOLE, _NEGATIVE, _TOO_LARGE, _POLARITY, _TIME_BACK, _TIME_RANGE = range(9)
# Fields of the parser's ``info`` array.
_STATUS, _LINE, _LINE_START, _LINE_END, _COLUMN, _TOKEN_START, _TOKEN_END, _PREV_LINE, _ROUNDED = range(9)


@njit(cache=True)
def _is_space(c) -> bool:
    """Space, tab, CR, or a comma: a CSV of events reads as the other text tables do (docs/formats.md)."""
    return c == 32 or c == 9 or c == 13 or c == 44


@njit(cache=True)
def _scan_number(buf, start, end, i64_max):
    """Parse ``buf[start:end]`` as ``[+-]digits[.digits][e[+-]digits]``.

    Returns ``(ok, negative, mantissa, exp10, next_digit, sticky)``: the value is
    ``mantissa * 10**exp10`` plus the digits that did not fit in the int64 mantissa,
    of which ``next_digit`` is the first (-1 when none) and ``sticky`` says whether any
    of them is not 0. Nothing is silently lost: callers round or refuse with these.
    """
    i = start
    negative = False
    if i < end and (buf[i] == 45 or buf[i] == 43):
        negative = buf[i] == 45
        i += 1
    mantissa = np.int64(0)
    exp10 = 0
    digits = 0
    full = False
    next_digit = -1
    sticky = False
    fraction = False
    while i < end:
        c = buf[i]
        if c == 46 and not fraction:
            fraction = True
            i += 1
            continue
        if not 48 <= c <= 57:
            break
        d = np.int64(c - 48)
        if not full and mantissa <= (i64_max - d) // 10:
            mantissa = mantissa * 10 + d
            if fraction:
                exp10 -= 1
        else:
            full = True
            if next_digit < 0:
                next_digit = d
            elif d != 0:
                sticky = True
            if not fraction:
                exp10 += 1
        digits += 1
        i += 1
    if next_digit > 0:
        sticky = True
    if digits == 0:
        return False, negative, mantissa, exp10, next_digit, sticky
    if i < end and (buf[i] == 101 or buf[i] == 69):
        i += 1
        exp_negative = False
        if i < end and (buf[i] == 45 or buf[i] == 43):
            exp_negative = buf[i] == 45
            i += 1
        exponent = 0
        exp_digits = 0
        while i < end and 48 <= buf[i] <= 57:
            if exponent < 10000:
                exponent = exponent * 10 + np.int64(buf[i] - 48)
            exp_digits += 1
            i += 1
        if exp_digits == 0:
            return False, negative, mantissa, exp10, next_digit, sticky
        exp10 += -exponent if exp_negative else exponent
    return i == end, negative, mantissa, exp10, next_digit, sticky


@njit(cache=True)
def _to_microseconds(negative, mantissa, exp10, next_digit, sticky, pow10, max_time):
    """Seconds as integer µs, half away from zero: ``(ok, value, rounded)``.

    ``ok`` is False when ``|value| >= max_time``; ``rounded`` when sub-µs digits were not 0.
    """
    scale = exp10 + 6
    rounded = sticky
    if mantissa == 0 and not sticky:
        return True, np.int64(0), False
    if scale > 0:
        if sticky or scale > 18 or mantissa >= max_time // pow10[scale] + 1:
            return False, np.int64(0), False  # digits at or above 1 µs were cut: far out of range
        value = mantissa * pow10[scale]
    elif scale == 0:
        value = mantissa + (1 if next_digit >= 5 else 0)
    elif -scale > 19:
        value = np.int64(0)  # below 0.1 µs (the mantissa has at most 19 digits)
        rounded = True
    elif -scale == 19:
        value = np.int64(1) if mantissa >= 5 * pow10[18] else np.int64(0)
        rounded = True
    else:
        p = pow10[-scale]
        value = mantissa // p
        remainder = mantissa - value * p
        rounded = rounded or remainder != 0
        if 2 * remainder >= p:
            value += 1
    if value >= max_time:
        return False, np.int64(0), False
    return True, -value if negative else value, rounded


@njit(cache=True)
def _to_whole(negative, mantissa, exp10, sticky, pow10):
    """An integer field: ``(status, value)``; values past 1e6 only need to be known as too large."""
    if mantissa == 0 and not sticky:
        return _OK, np.int64(0)
    if exp10 >= 0:
        if exp10 > 6 or mantissa > 1000000:
            return _TOO_LARGE, np.int64(0)
        value = mantissa * pow10[exp10]
    else:
        if sticky or -exp10 > 18 or mantissa % pow10[-exp10] != 0:
            return _NOT_WHOLE, np.int64(0)
        value = mantissa // pow10[-exp10]
    if value > 1000000:
        return _TOO_LARGE, np.int64(0)
    return _OK, -value if negative else value


@njit(cache=True)
def _parse_events(buf, t, x, y, p, info, pow10, i64_max, max_coord, max_time):
    """Parse ``t x y p`` lines of ``buf`` into the arrays; returns the number of events.

    On the first bad line, stops and fills ``info`` (status, line, where). Counts the
    times rounded to the µs in ``info[_ROUNDED]``.
    """
    n_bytes = buf.shape[0]
    starts = np.empty(4, dtype=np.int64)
    ends = np.empty(4, dtype=np.int64)
    pos = 0
    line = 0
    n = 0
    prev_t = np.int64(0)
    prev_line = 0
    while pos < n_bytes:
        line += 1
        end = pos
        while end < n_bytes and buf[end] != 10:
            end += 1
        info[_LINE] = line
        info[_LINE_START] = pos
        info[_LINE_END] = end
        i = pos
        while i < end and _is_space(buf[i]):
            i += 1
        if i == end or buf[i] == 35:  # blank or '#' comment
            pos = end + 1
            continue
        columns = 0
        while i < end:
            start = i
            while i < end and not _is_space(buf[i]):
                i += 1
            if columns < 4:
                starts[columns] = start
                ends[columns] = i
            columns += 1
            while i < end and _is_space(buf[i]):
                i += 1
        if columns < 4:  # columns past the 4th are ignored (see docs/formats.md)
            info[_STATUS] = _COLUMN_COUNT
            info[_COLUMN] = columns
            return n
        for c in range(4):
            info[_COLUMN] = c
            info[_TOKEN_START] = starts[c]
            info[_TOKEN_END] = ends[c]
            ok, negative, mantissa, exp10, next_digit, sticky = _scan_number(buf, starts[c], ends[c], i64_max)
            if not ok:
                info[_STATUS] = _NOT_NUMBER
                return n
            if c == 0:
                ok, value, rounded = _to_microseconds(negative, mantissa, exp10, next_digit, sticky, pow10, max_time)
                if not ok:
                    info[_STATUS] = _TIME_RANGE
                    return n
                if rounded:
                    info[_ROUNDED] += 1
                if n > 0 and value < prev_t:
                    info[_STATUS] = _TIME_BACK
                    info[_PREV_LINE] = prev_line
                    return n
                t[n] = value
                continue
            if negative and (mantissa != 0 or sticky) and c < 3:
                info[_STATUS] = _NEGATIVE
                return n
            status, value = _to_whole(negative, mantissa, exp10, sticky, pow10)
            if status != 0:
                info[_STATUS] = status
                return n
            if c < 3:
                if value > max_coord:
                    info[_STATUS] = _TOO_LARGE
                    return n
                if c == 1:
                    x[n] = value
                else:
                    y[n] = value
            elif value == 1:
                p[n] = 1
            elif value == 0 or value == -1:
                p[n] = 0
            else:
                info[_STATUS] = _POLARITY
                return n
        prev_t = t[n]
        prev_line = line
        n += 1
        pos = end + 1
    info[_STATUS] = _OK
    return n


#: What ``Recording.notes`` says when times were rounded (``{count}``, ``{name}``).
ROUNDED_NOTE = ("{name}: {count:,} time(s) had digits below 1 µs; rounded to the nearest µs, "
                "halves away from zero")


def read_events_txt(path: str | Path, notes: list[str] | None = None) -> np.ndarray:
    """Read ECD ``events.txt``: lines ``t x y p`` (t seconds, x column, y row, p 0/1 or -1/1).

    Columns after the fourth are ignored. Returns an ``EVENT_DTYPE`` array with ``t`` in
    integer microseconds, converted from the decimal text exactly and rounded half away
    from zero; when ``notes`` is given, a line saying how many times were rounded is
    appended to it. Blank lines and ``#`` comments are skipped. Raises ``DataError``
    naming the line for a malformed line, a negative or >65535 coordinate, a polarity
    outside {-1, 0, 1}, a timestamp earlier than the previous line's or outside
    ``|t| < MAX_TIME_US``, or a file without events.
    """
    path = Path(path)
    data = read_bytes(path, "events file")
    events, info = parse_lines(np.frombuffer(data, dtype=np.uint8), data.count(b"\n") + 1)
    if info[_STATUS] != _OK:
        raise DataError(_describe(path, data, info))
    if len(events) == 0:
        what = "the file is empty" if not data.strip() else "only blank lines and # comments"
        raise DataError(located(path, None, f"no events ({what}); expected lines of {_EXPECTED}"))
    if info[_ROUNDED] and notes is not None:
        notes.append(ROUNDED_NOTE.format(name=path.name, count=int(info[_ROUNDED])))
    return events


def parse_lines(buf: np.ndarray, capacity: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The events of the ``t x y p`` lines in ``buf`` (uint8) and the parser's ``info`` (``info[0]``
    is 0 when every line was good; else the events before the first bad line). ``capacity``:
    at least the number of lines (counted when not given)."""
    if capacity is None:  # counted in pieces: no temporary the size of the buffer
        capacity = 1 + sum(int(np.count_nonzero(buf[k:k + (1 << 24)] == 10)) for k in range(0, len(buf), 1 << 24))
    t = np.empty(capacity, dtype=np.int64)
    x = np.empty(capacity, dtype=np.uint16)
    y = np.empty(capacity, dtype=np.uint16)
    p = np.empty(capacity, dtype=np.uint8)
    info = np.zeros(9, dtype=np.int64)
    n = _parse_events(buf, t, x, y, p, info, _POW10, _I64_MAX, _MAX_COORD, _MAX_TIME_US)
    events = np.empty(n, dtype=EVENT_DTYPE)
    events["t"], events["x"], events["y"], events["p"] = t[:n], x[:n], y[:n], p[:n]
    return events, info


def _describe(path: Path, data: bytes, info: np.ndarray) -> str:
    """The one-line message for the parser's error ``info``."""
    # Only the offending field is quoted (cut to 40 characters), never the line: the
    # file may not be an events file at all.
    status, line = int(info[_STATUS]), int(info[_LINE])
    text = data[info[_TOKEN_START]:info[_TOKEN_END]].decode("utf-8", "replace")
    quoted = quote_field(path, text)
    token = text if len(text) <= 40 else text[:37] + "..."
    name = _COLUMNS[int(info[_COLUMN])] if status != _COLUMN_COUNT else ""
    messages = {
        _COLUMN_COUNT: f"expected {_EXPECTED}, found {int(info[_COLUMN])} column(s)",
        _NOT_NUMBER: f"column '{name}': expected a number, got {quoted}",
        _NOT_WHOLE: f"column '{name}': expected a whole number, got {quoted}",
        _NEGATIVE: f"column '{name}': pixel coordinates must be >= 0, got {token}",
        _TOO_LARGE: f"column '{name}': expected at most {_MAX_COORD}, got {token}",
        _POLARITY: f"column 'p': polarity must be 0 or 1 (or -1 for OFF), got {token}",
        _TIME_BACK: f"time goes back: t = {token} s is earlier than the previous event "
                    f"(line {int(info[_PREV_LINE])}); events must be sorted by time",
        _TIME_RANGE: f"column 't': time {token} s is out of range (|t| < 2**61 µs, about 2.3e12 s)",
    }
    return located(path, line, messages[status])


@njit(cache=True)
def _put_digits(out, k, value):
    if value == 0:
        out[k] = 48
        return k + 1
    digits = 0
    v = value
    while v > 0:
        digits += 1
        v //= 10
    for j in range(digits - 1, -1, -1):
        out[k + j] = 48 + value % 10
        value //= 10
    return k + digits


@njit(cache=True)
def _format_events(t, x, y, p, out):
    """``t x y p`` lines into ``out``, t in seconds with 9 decimals as ECD writes it."""
    k = 0
    for i in range(t.shape[0]):
        value = t[i]
        if value < 0:
            out[k] = 45
            k += 1
            value = -value
        k = _put_digits(out, k, value // 1000000)
        out[k] = 46
        k += 1
        fraction = value % 1000000
        divisor = 100000
        for _ in range(6):
            out[k] = 48 + (fraction // divisor) % 10
            divisor //= 10
            k += 1
        for _ in range(3):
            out[k] = 48
            k += 1
        out[k] = 32
        k = _put_digits(out, k + 1, np.int64(x[i]))
        out[k] = 32
        k = _put_digits(out, k + 1, np.int64(y[i]))
        out[k] = 32
        out[k + 1] = 48 + p[i]
        out[k + 2] = 10
        k += 3
    return k


def write_events_txt(path: str | Path, events: np.ndarray, chunk: int = 1_000_000) -> None:
    """Write ECD ``events.txt``: ``t x y p`` per line, t in seconds with 9 decimals."""
    events = check_writable(events)
    # A line is at most 1 + 19 + 1 + 9 + 3 * (1 + 5) + 1 bytes; 56 leaves room.
    with atomic_write(path) as handle:
        for start in range(0, len(events), chunk):
            part = events[start:start + chunk]
            out = np.empty(56 * len(part) + 4, dtype=np.uint8)
            k = _format_events(np.ascontiguousarray(part["t"]), np.ascontiguousarray(part["x"]),
                               np.ascontiguousarray(part["y"]), np.ascontiguousarray(part["p"]), out)
            handle.write(out[:k].tobytes())
