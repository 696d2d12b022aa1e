"""Event files: ECD ``events.txt`` and numpy ``.npy``/``.npz``, read into ``EVENT_DTYPE``.

The text reader parses the raw bytes in one compiled pass (no Python per line) and
converts the decimal seconds to integer microseconds exactly, without going through
a float: ``1468939993.0674165`` s becomes ``1468939993067417`` µs (half away from zero).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
from numba import njit

from tofnet.errors import DataError, located
from tofnet.events import EVENT_DTYPE

_COLUMNS = ("t", "x", "y", "p")
_EXPECTED = "4 columns 't x y p' (seconds, column px, row px, polarity 0/1)"
_MAX_COORD = 65535  # uint16
_POW10 = np.array([10 ** k for k in range(19)], dtype=np.int64)
_I64_MAX = np.iinfo(np.int64).max

# Status codes of the compiled parser.
_OK, _COLUMN_COUNT, _NOT_NUMBER, _NOT_WHOLE, _NEGATIVE, _TOO_LARGE, _POLARITY, _TIME_BACK, _TIME_RANGE = range(9)
# Fields of the parser's ``info`` array.
_STATUS, _LINE, _LINE_START, _LINE_END, _COLUMN, _TOKEN_START, _TOKEN_END, _PREV_LINE = range(8)


@njit(cache=True)
def _is_space(c) -> bool:
    return c == 32 or c == 9 or c == 13


@njit(cache=True)
def _scan_number(buf, start, end):
    """Parse ``buf[start:end]`` as ``[+-]digits[.digits][e[+-]digits]``.

    Returns ``(ok, negative, mantissa, exp10)`` with value ``mantissa * 10**exp10``;
    digits past the 18th significant one are dropped (far below a microsecond).
    """
    i = start
    negative = False
    if i < end and (buf[i] == 45 or buf[i] == 43):
        negative = buf[i] == 45
        i += 1
    mantissa = np.int64(0)
    exp10 = 0
    digits = 0
    significant = 0
    while i < end and 48 <= buf[i] <= 57:
        if significant < 18:
            mantissa = mantissa * 10 + np.int64(buf[i] - 48)
            if mantissa > 0:
                significant += 1
        else:
            exp10 += 1
        digits += 1
        i += 1
    if i < end and buf[i] == 46:
        i += 1
        while i < end and 48 <= buf[i] <= 57:
            if significant < 18:
                mantissa = mantissa * 10 + np.int64(buf[i] - 48)
                exp10 -= 1
                if mantissa > 0:
                    significant += 1
            digits += 1
            i += 1
    if digits == 0:
        return False, negative, mantissa, exp10
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
            return False, negative, mantissa, exp10
        exp10 += -exponent if exp_negative else exponent
    return i == end, negative, mantissa, exp10


@njit(cache=True)
def _to_microseconds(negative, mantissa, exp10, pow10, i64_max):
    """Seconds ``±mantissa * 10**exp10`` as integer µs, half away from zero: ``(ok, value)``."""
    if mantissa == 0:
        return True, np.int64(0)
    scale = exp10 + 6
    if scale >= 0:
        if scale > 18 or mantissa > i64_max // pow10[scale]:
            return False, np.int64(0)
        value = mantissa * pow10[scale]
    elif -scale > 18:
        value = np.int64(0)  # below 0.1 µs
    else:
        p = pow10[-scale]
        value = mantissa // p
        if 2 * (mantissa - value * p) >= p:
            value += 1
    return True, -value if negative else value


@njit(cache=True)
def _to_whole(negative, mantissa, exp10, pow10):
    """An integer field: ``(status, value)``; values past 1e6 only need to be known as too large."""
    if mantissa == 0:
        return _OK, np.int64(0)
    if exp10 >= 0:
        if exp10 > 6 or mantissa > 1000000:
            return _TOO_LARGE, np.int64(0)
        value = mantissa * pow10[exp10]
    else:
        if -exp10 > 18 or mantissa % pow10[-exp10] != 0:
            return _NOT_WHOLE, np.int64(0)
        value = mantissa // pow10[-exp10]
    if value > 1000000:
        return _TOO_LARGE, np.int64(0)
    return _OK, -value if negative else value


@njit(cache=True)
def _parse_events(buf, t, x, y, p, info, pow10, i64_max, max_coord):
    """Parse ``t x y p`` lines of ``buf`` into the arrays; returns the number of events.

    On the first bad line, stops and fills ``info`` (status, line, where).
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
            ok, negative, mantissa, exp10 = _scan_number(buf, starts[c], ends[c])
            if not ok:
                info[_STATUS] = _NOT_NUMBER
                return n
            if c == 0:
                ok, value = _to_microseconds(negative, mantissa, exp10, pow10, i64_max)
                if not ok:
                    info[_STATUS] = _TIME_RANGE
                    return n
                if n > 0 and value < prev_t:
                    info[_STATUS] = _TIME_BACK
                    info[_PREV_LINE] = prev_line
                    return n
                t[n] = value
                continue
            if negative and mantissa != 0 and c < 3:
                info[_STATUS] = _NEGATIVE
                return n
            status, value = _to_whole(negative, mantissa, exp10, pow10)
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


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise DataError(located(path, None, "file not found")) from None
    except IsADirectoryError:
        raise DataError(located(path, None, "is a folder, expected an events file")) from None
    except OSError as err:
        raise DataError(located(path, None, f"cannot read: {err.strerror or err}")) from None


def read_events_txt(path: str | Path) -> np.ndarray:
    """Read ECD ``events.txt``: lines ``t x y p`` (t seconds, x column, y row, p 0/1 or -1/1).

    Columns after the fourth are ignored. Returns an ``EVENT_DTYPE`` array with ``t`` in integer microseconds. Blank lines
    and ``#`` comments are skipped. Raises ``DataError`` naming the line for a
    malformed line, a negative or >65535 coordinate, a polarity outside {-1, 0, 1},
    a timestamp earlier than the previous line's, or a file without events.
    """
    path = Path(path)
    data = _read_bytes(path)
    buf = np.frombuffer(data, dtype=np.uint8)
    capacity = data.count(b"\n") + 1
    t = np.empty(capacity, dtype=np.int64)
    x = np.empty(capacity, dtype=np.uint16)
    y = np.empty(capacity, dtype=np.uint16)
    p = np.empty(capacity, dtype=np.uint8)
    info = np.zeros(8, dtype=np.int64)
    n = _parse_events(buf, t, x, y, p, info, _POW10, _I64_MAX, _MAX_COORD)
    if info[_STATUS] != _OK:
        raise DataError(_describe(path, data, info))
    if n == 0:
        what = "the file is empty" if not data.strip() else "only blank lines and # comments"
        raise DataError(located(path, None, f"no events ({what}); expected lines of {_EXPECTED}"))
    events = np.empty(n, dtype=EVENT_DTYPE)
    events["t"], events["x"], events["y"], events["p"] = t[:n], x[:n], y[:n], p[:n]
    return events


def _describe(path: Path, data: bytes, info: np.ndarray) -> str:
    """The one-line message for the parser's error ``info``."""
    status, line = int(info[_STATUS]), int(info[_LINE])
    text = data[info[_LINE_START]:info[_LINE_END]].decode("utf-8", "replace").strip()
    text = text if len(text) <= 80 else text[:77] + "..."
    token = data[info[_TOKEN_START]:info[_TOKEN_END]].decode("utf-8", "replace")
    name = _COLUMNS[int(info[_COLUMN])] if status != _COLUMN_COUNT else ""
    messages = {
        _COLUMN_COUNT: f"expected {_EXPECTED}, found {int(info[_COLUMN])} column(s): {text!r}",
        _NOT_NUMBER: f"column '{name}': expected a number, got {token!r}",
        _NOT_WHOLE: f"column '{name}': expected a whole number, got {token!r}",
        _NEGATIVE: f"column '{name}': pixel coordinates must be >= 0, got {token}",
        _TOO_LARGE: f"column '{name}': expected at most {_MAX_COORD}, got {token}",
        _POLARITY: f"column 'p': polarity must be 0 or 1 (or -1 for OFF), got {token}",
        _TIME_BACK: f"time goes back: t = {token} s is earlier than the previous event "
                    f"(line {int(info[_PREV_LINE])}); events must be sorted by time",
        _TIME_RANGE: f"column 't': time {token} s is out of range",
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


def _check_writable(events: np.ndarray) -> np.ndarray:
    if not isinstance(events, np.ndarray) or events.dtype != EVENT_DTYPE:
        raise TypeError(f"events must be an array of dtype {EVENT_DTYPE}, got {getattr(events, 'dtype', type(events))}")
    if np.any(events["p"] > 1):
        raise DataError(f"polarity must be 0 or 1, got {int(events['p'].max())}")
    return events


def write_events_txt(path: str | Path, events: np.ndarray, chunk: int = 1_000_000) -> None:
    """Write ECD ``events.txt``: ``t x y p`` per line, t in seconds with 9 decimals."""
    events = _check_writable(events)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # A line is at most 1 + 19 + 1 + 9 + 3 * (1 + 5) + 1 bytes; 56 leaves room.
    with open(path, "wb") as handle:
        for start in range(0, len(events), chunk):
            part = events[start:start + chunk]
            out = np.empty(56 * len(part) + 4, dtype=np.uint8)
            k = _format_events(np.ascontiguousarray(part["t"]), np.ascontiguousarray(part["x"]),
                               np.ascontiguousarray(part["y"]), np.ascontiguousarray(part["p"]), out)
            handle.write(out[:k].tobytes())


def read_events_npy(path: str | Path, columns: str | tuple[str, ...] | None = None) -> np.ndarray:
    """Read events from ``.npy`` or ``.npz`` into ``EVENT_DTYPE`` (t in µs).

    ``.npy``: a structured array with fields ``t x y p``, or an ``(n, 4)`` array of
    columns ``t x y p`` (another order: ``columns="x,y,t,p"``). ``.npz``: a structured
    array under key ``events`` or ``event_data``, or arrays ``t``, ``x``, ``y``, ``p``.
    The polarity may be named ``p``, ``on`` or ``polarity`` (``tofnet.io.arrays``).
    A float ``t`` is seconds, an integer ``t`` microseconds.
    Polarity -1 maps to 0 (OFF); booleans are accepted.
    """
    from tofnet.io.arrays import PlainColumns, columns_of, npz_columns

    path = Path(path)
    try:
        loaded = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise DataError(located(path, None, "file not found")) from None
    except IsADirectoryError:
        raise DataError(located(path, None, "is a folder, expected an events file")) from None
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
        raise DataError(located(path, None, f"not a readable .npy/.npz file ({err})")) from None
    if isinstance(loaded, np.lib.npyio.NpzFile):
        with loaded:
            try:
                arrays = npz_columns(path, loaded, columns)
            except (ValueError, OSError, zipfile.BadZipFile) as err:
                raise DataError(located(path, None, f"cannot read array ({err})")) from None
    else:
        arrays = columns_of(path, loaded, "the array", columns)
    try:
        return events_from_columns(arrays, path)
    except DataError as err:
        if columns is None and isinstance(arrays, PlainColumns):
            raise DataError(f"{err} (a plain (n, 4) array is read as columns t x y p; "
                            "for another order pass --columns, e.g. x,y,t,p)") from None
        raise


def events_from_columns(columns: dict[str, np.ndarray], source: object = "<memory>") -> np.ndarray:
    """Validate columns ``t x y p`` and build an ``EVENT_DTYPE`` array.

    Float ``t`` is seconds (rounded to the nearest µs, half away from zero), integer
    ``t`` microseconds. Errors name the field and the (0-based) event index.
    """
    arrays = {name: np.asarray(columns[name]) for name in _COLUMNS}
    lengths = {name: a.shape for name, a in arrays.items()}
    n = arrays["t"].shape[0] if arrays["t"].ndim == 1 else -1
    if any(a.shape != (n,) for a in arrays.values()):
        raise DataError(located(source, None, f"t, x, y, p must be 1-D arrays of one length, got shapes {lengths}"))
    if n == 0:
        raise DataError(located(source, None, "no events (the arrays are empty)"))

    def fail(name: str, index: int, message: str) -> DataError:
        return DataError(located(source, None, f"field '{name}', event {index}: {message}"))

    for name, a in arrays.items():
        if a.dtype.kind not in "biuf":
            raise DataError(located(source, None, f"field '{name}': expected numbers, got dtype {a.dtype}"))
        if a.dtype.kind == "f":
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise fail(name, int(bad[0]), f"expected a finite number, got {a[bad[0]]}")
    t = arrays["t"]
    if t.dtype.kind == "f":
        if np.max(np.abs(t)) >= 9e12:
            i = int(np.argmax(np.abs(t)))
            raise fail("t", i, f"{t[i]:g} s is out of range (float t is seconds)")
        scaled = t.astype(np.float64) * 1e6
        t_us = (np.sign(scaled) * np.floor(np.abs(scaled) + 0.5)).astype(np.int64)
    else:
        t_us = t.astype(np.int64)
    back = np.flatnonzero(np.diff(t_us) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise fail("t", i, f"time goes back ({t_us[i]} µs after {t_us[i - 1]} µs); events must be sorted by time")
    for name in ("x", "y"):
        a = arrays[name]
        checks = [(a < 0, "pixel coordinates must be >= 0"), (a > _MAX_COORD, f"expected at most {_MAX_COORD}")]
        if a.dtype.kind == "f":
            checks.append((a != np.floor(a), "expected a whole number"))
        for mask, message in checks:
            bad = np.flatnonzero(mask)
            if bad.size:
                raise fail(name, int(bad[0]), f"{message}, got {a[bad[0]]}")
    p = arrays["p"]
    bad = np.flatnonzero((p != 0) & (p != 1) & (p != -1))
    if bad.size:
        raise fail("p", int(bad[0]), f"polarity must be 0 or 1 (or -1 for OFF), got {p[bad[0]]}")
    events = np.empty(n, dtype=EVENT_DTYPE)
    events["t"] = t_us
    events["x"] = arrays["x"]
    events["y"] = arrays["y"]
    events["p"] = p == 1
    return events


def write_events_npy(path: str | Path, events: np.ndarray) -> None:
    """Write events: ``.npy`` a structured ``EVENT_DTYPE`` array; ``.npz`` arrays ``t`` (int64 µs), ``x``, ``y``, ``p``."""
    events = _check_writable(events)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".npy":
        np.save(path, events)
    elif path.suffix == ".npz":
        np.savez(path, **{name: np.ascontiguousarray(events[name]) for name in _COLUMNS})
    else:
        raise DataError(located(path, None, "expected a .npy or .npz file name"))
