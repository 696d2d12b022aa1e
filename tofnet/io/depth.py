"""Depth estimates to and from ``.npz`` and ``.csv`` files.

Both are written atomically. A truncated file is never read as complete: a ``.npz`` is
checked by zip (central directory, CRC-32 of every array); a ``.csv`` ends with the
line ``# end: N rows``, which must be present, last, and agree with the rows read.
Values read back are checked (times in range, whole pixels, finite depths).
"""

from __future__ import annotations

import json
import re
from decimal import ROUND_HALF_UP, Decimal, InvalidOperation
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tofnet.errors import DataError, located, quote_field
from tofnet.events import DEPTH_DTYPE, MAX_TIME_US
from tofnet.io.files import write_text_atomic
from tofnet.io.groundtruth import read_text
from tofnet.io.jsontext import parse_json
from tofnet.io.npy import Column, load_npz, write_npz
from tofnet.units import MAX_PERIOD_S

CSV_HEADER = "t,x,y,z,step"
#: Estimates per slice when a depth file is written (bounded memory for any number of them).
PIECE = 1 << 20
#: The last line of a depth CSV; a file without it (or with another count) is refused.
CSV_END = "# end: {rows} rows"
_CSV_END = re.compile(r"^# end: (\d{1,19}) rows$")
_META = ("t0_us", "timestep_us", "latency_steps")
_ARRAYS = ("t", "t_us", "x", "y", "z", "step")
#: Below this |t| (µs) a float64 holds every µs exactly; larger CSV times are parsed as decimals.
_FLOAT_EXACT_US = 2**52
#: Largest ``latency_steps`` a depth file (or ``--latency-steps``) may give: a chain of a million processes.
MAX_LATENCY_STEPS = 1_000_000


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot store {type(value).__name__} in the depth summary")


def write_depth(path: str | Path, depth: np.ndarray, *, t0_us: int, timestep_us: int, latency_steps: int,
                summary: dict | None = None) -> None:
    """Write depth estimates (``DEPTH_DTYPE``) to ``.npz`` or ``.csv``, chosen by suffix, atomically.

    ``.npz``: arrays ``t`` (float64 s), ``t_us`` (int64 µs, exact), ``x``, ``y``
    (uint16 px), ``z`` (float64 m), ``step`` (int64) and scalars ``t0_us``,
    ``timestep_us``, ``latency_steps`` and ``summary_json`` (JSON text of ``summary``).
    ``.csv``: header ``t,x,y,z,step``, ``t`` in seconds with 6 decimals (exact for
    µs stamps), ``z`` in metres (shortest round-tripping text), then the line
    ``# end: N rows``; no metadata.
    """
    path = Path(path)
    if not isinstance(depth, np.ndarray) or depth.dtype != DEPTH_DTYPE:
        raise TypeError(f"depth must be an array of dtype {DEPTH_DTYPE}, got {getattr(depth, 'dtype', type(depth))}")
    if path.suffix.lower() not in (".npz", ".csv"):
        raise DataError(located(path, None, "depth output must be a .npz or .csv file"))
    if path.suffix.lower() == ".npz":
        try:
            summary_json = json.dumps(summary or {}, default=_jsonable)
        except (TypeError, ValueError) as err:
            raise DataError(located(path, None, f"summary is not JSON-serialisable: {err}")) from None
        def column(dtype, of):  # written a slice at a time: depth may be a memory map larger than memory
            return Column(dtype, len(depth), lambda: (of(depth[lo:lo + PIECE]) for lo in range(0, len(depth), PIECE)))
        write_npz(path, dict(t=column(np.float64, lambda d: d["t"] * 1e-6), t_us=column(np.int64, lambda d: d["t"]),
                             x=column(np.uint16, lambda d: d["x"]), y=column(np.uint16, lambda d: d["y"]),
                             z=column(np.float64, lambda d: d["z"]), step=column(np.int64, lambda d: d["step"]),
                             t0_us=np.int64(t0_us), timestep_us=np.int64(timestep_us),
                             latency_steps=np.int64(latency_steps), summary_json=np.str_(summary_json)))
        return
    rows = [f"{_seconds(t)},{x},{y},{z!r},{s}" for t, x, y, z, s in
            zip(depth["t"].tolist(), depth["x"].tolist(), depth["y"].tolist(), depth["z"].tolist(),
                depth["step"].tolist())]
    write_text_atomic(path, "\n".join([CSV_HEADER, *rows, CSV_END.format(rows=len(rows))]) + "\n")


def _seconds(t_us: int) -> str:
    """Integer µs as seconds with 6 decimals, exactly (no float rounding)."""
    sign = "-" if t_us < 0 else ""
    whole, fraction = divmod(abs(t_us), 1_000_000)
    return f"{sign}{whole}.{fraction:06d}"


def read_depth(path: str | Path) -> tuple[np.ndarray, dict]:
    """Read depth estimates written by ``write_depth``.

    Returns ``(depth, meta)``: ``depth`` a ``DEPTH_DTYPE`` array (``t`` in µs) and
    ``meta`` with ``t0_us``, ``timestep_us``, ``latency_steps`` (None when the file
    does not hold them, as in CSV) and ``summary`` (a dict, None for CSV).
    """
    path = Path(path)
    if path.suffix.lower() == ".npz":
        return _read_npz(path)
    if path.suffix.lower() == ".csv":
        return _read_csv(path), {**{key: None for key in _META}, "summary": None}
    raise DataError(located(path, None, "expected a .npz or .csv depth file"))


def _read_npz(path: Path) -> tuple[np.ndarray, dict]:
    _, arrays = load_npz(path, (*_ARRAYS, *_META, "summary_json"), "depth file")
    missing = [key for key in ("t", "x", "y", "z", "step") if key not in arrays]
    if missing:
        raise DataError(located(path, None, f"missing array(s) {', '.join(missing)}; expected t, x, y, z, step"))
    n = arrays["t"].shape[0] if arrays["t"].ndim == 1 else -1
    for key in _ARRAYS:
        if key not in arrays:
            continue
        if arrays[key].shape != (n,):
            raise DataError(located(path, None, f"array '{key}' has shape {arrays[key].shape}, expected ({n},) like 't'"))
        if arrays[key].dtype.kind not in ("iuf" if key in ("t", "z") else "iu"):
            raise DataError(located(path, None, f"array '{key}' has dtype {arrays[key].dtype}, expected "
                                                f"{'numbers' if key in ('t', 'z') else 'whole numbers'}"))
    if "t_us" in arrays:
        t_us = arrays["t_us"]
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            t_us = np.round(arrays["t"].astype(np.float64) * 1e6)
    columns = {"t": t_us, "x": arrays["x"], "y": arrays["y"], "z": arrays["z"], "step": arrays["step"]}
    depth = _checked(path, columns, row_line=None)
    meta: dict[str, Any] = {}
    for key in _META:
        value = arrays.get(key)
        if value is not None and (value.shape != () or value.dtype.kind not in "iu"
                                  or not -MAX_TIME_US < int(value) < MAX_TIME_US):
            raise DataError(located(path, None, f"'{key}' must be one whole number, |value| < 2**61"))
        meta[key] = None if value is None else int(value)
    check_timing(path, depth, meta)
    text = arrays.get("summary_json")
    if text is not None and (text.shape != () or text.dtype.kind != "U"):
        raise DataError(located(path, None, "'summary_json' must be one string"))
    text = "" if text is None else str(text)
    meta["summary"] = parse_json(text, path, "summary_json") if text.strip() else {}
    return depth, meta


def check_timing(path: object, depth: np.ndarray, meta: dict) -> None:
    """The timing of a depth file (or the options that complete a ``.csv``'s), in the ranges a run can have:
    ``timestep_us`` 1 µs to ``MAX_PERIOD_S``, ``latency_steps`` 0 to ``MAX_LATENCY_STEPS``, and every ``step``
    times ``timestep_us`` inside the time range (2**61 µs). ``eval`` and ``plot`` count their windows in steps
    times the timestep: a timestep of 2**60 µs made them ask for 336 TiB, and a larger product would wrap in
    int64. A one-line ``DataError`` naming the field; a value that is absent (``None``) is not checked."""
    timestep, latency = meta.get("timestep_us"), meta.get("latency_steps")
    longest = round(MAX_PERIOD_S * 1e6)
    if timestep is not None and not 1 <= timestep <= longest:
        raise DataError(located(path, None, f"'timestep_us' must be 1..{longest} µs (at most {MAX_PERIOD_S:g} s), "
                                            f"got {timestep}"))
    if latency is not None and not 0 <= latency <= MAX_LATENCY_STEPS:
        raise DataError(located(path, None, f"'latency_steps' must be 0..{MAX_LATENCY_STEPS:,}, got {latency}"))
    if timestep is not None and len(depth) and int(depth["step"].max()) * timestep >= MAX_TIME_US:
        last = int(depth["step"].max())
        raise DataError(located(path, None, f"array 'step' reaches {last}: {last} steps of {timestep} µs "
                                            f"('timestep_us') lie beyond the time range (2**61 µs)"))


def _checked(path: Path, columns: dict[str, np.ndarray], row_line: Callable[[int], int] | None) -> np.ndarray:
    """A ``DEPTH_DTYPE`` array from checked columns: ``t`` whole µs with ``|t| < 2**61``,
    ``x``, ``y`` whole pixels 0..65535, ``z`` finite metres, ``step`` a whole number >= 0."""
    def whole(a, low, high):
        return (a >= low) & (a <= high) & (a == np.round(a)) if a.dtype.kind == "f" else (a >= low) & (a <= high)

    checks = (("t", lambda a: whole(a, -MAX_TIME_US + 1, MAX_TIME_US - 1), "whole µs with |t| < 2**61"),
              ("x", lambda a: whole(a, 0, 65535), "a whole number 0..65535"),
              ("y", lambda a: whole(a, 0, 65535), "a whole number 0..65535"),
              ("z", lambda a: np.isfinite(a) if a.dtype.kind == "f" else np.ones(a.shape, bool), "a finite depth"),
              ("step", lambda a: whole(a, 0, MAX_TIME_US - 1), "a whole number >= 0"))
    for name, ok, expected in checks:
        values = columns[name]
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(~ok(values))
        if bad.size:
            row = int(bad[0])
            if row_line is None:
                raise DataError(located(path, None, f"array '{name}', row {row}: expected {expected}, "
                                                    f"got {values[row]}"))
            raise DataError(located(path, row_line(row), f"column '{name}': expected {expected}, "
                                                         f"got {values[row]:.17g}"))
    depth = np.empty(len(columns["t"]), dtype=DEPTH_DTYPE)
    for name in ("t", "x", "y", "z", "step"):
        depth[name] = columns[name]
    return depth


def _read_csv(path: Path) -> np.ndarray:
    text = read_text(path)
    lines = text.splitlines()
    if not lines or lines[0].strip().replace(" ", "") != CSV_HEADER:
        first = lines[0].strip() if lines else ""
        raise DataError(located(path, 1, f"expected the header '{CSV_HEADER}', got {quote_field(path, first)}"))
    last = len(lines) - 1
    while last > 0 and not lines[last].strip():
        last -= 1
    end = _CSV_END.match(lines[last].strip()) if last > 0 else None
    if end is None or not text.endswith(("\n", "\r")):
        raise DataError(located(path, None, f"no end line '{CSV_END.format(rows='N')}': the file is truncated "
                                            "(or was not written by tofnet; add that line to read it)"))
    lines = lines[:last]
    rows = sum(1 for line in lines[1:] if line.strip())
    if rows != int(end.group(1)):
        raise DataError(located(path, last + 1, f"the end line says {int(end.group(1))} rows but the file holds "
                                                f"{rows}: truncated or edited"))
    if rows == 0:
        return np.empty(0, dtype=DEPTH_DTYPE)
    try:
        table = np.loadtxt(lines[1:], delimiter=",", dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        _raise_first_bad_row(path, lines)
        raise DataError(located(path, None, f"cannot parse the rows as '{CSV_HEADER}'")) from None
    if table.shape[1] != 5:
        _raise_first_bad_row(path, lines)
    with np.errstate(over="ignore", invalid="ignore"):
        t_us = np.round(table[:, 0] * 1e6)
    if not np.all(np.abs(t_us) < _FLOAT_EXACT_US):
        t_us = _exact_microseconds(path, lines)
    columns = {"t": t_us, "x": table[:, 1], "y": table[:, 2], "z": table[:, 3], "step": table[:, 4]}
    return _checked(path, columns, row_line=lambda row: _line_of_row(lines, row))


def _exact_microseconds(path: Path, lines: list[str]) -> np.ndarray:
    """The ``t`` column as µs from the decimal text (rounded half away from zero), for times
    a float64 cannot hold to the µs; values out of range become ``±2**61`` (then refused)."""
    out = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        try:
            value = Decimal(line.split(",", 1)[0].strip()) * 1_000_000
        except InvalidOperation:
            raise DataError(located(path, number, "column 't': expected a number")) from None
        if not value.is_finite() or abs(value) >= MAX_TIME_US:
            out.append(MAX_TIME_US if not value.is_signed() else -MAX_TIME_US)
        else:
            out.append(int(value.to_integral_value(rounding=ROUND_HALF_UP)))  # half away from zero
    return np.array(out, dtype=object).astype(np.int64)


def _line_of_row(lines: list[str], row: int) -> int:
    """1-based line number of data row ``row`` (blank lines are skipped by loadtxt)."""
    seen = -1
    for number, line in enumerate(lines[1:], start=2):
        if line.strip():
            seen += 1
            if seen == row:
                return number
    return len(lines)


def _raise_first_bad_row(path: Path, lines: list[str]) -> None:
    """Find and report the first malformed CSV row (the slow path, only after a failure)."""
    names = CSV_HEADER.split(",")
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != len(names):
            raise DataError(located(path, number, f"expected 5 columns '{CSV_HEADER}', found {len(fields)}"))
        for name, field in zip(names, fields):
            try:
                float(field)
            except ValueError:
                raise DataError(located(path, number, f"column '{name}': expected a number, "
                                                      f"got {quote_field(path, field.strip())}")) from None
