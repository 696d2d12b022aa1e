"""Depth estimates to and from ``.npz`` and ``.csv`` files."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from tofnet.errors import DataError, located
from tofnet.events import DEPTH_DTYPE
from tofnet.io.groundtruth import read_text

CSV_HEADER = "t,x,y,z,step"
_META = ("t0_us", "timestep_us", "latency_steps")


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
    """Write depth estimates (``DEPTH_DTYPE``) to ``.npz`` or ``.csv``, chosen by suffix.

    ``.npz``: arrays ``t`` (float64 s), ``t_us`` (int64 µs, exact), ``x``, ``y``
    (uint16 px), ``z`` (float64 m), ``step`` (int64) and scalars ``t0_us``,
    ``timestep_us``, ``latency_steps`` and ``summary_json`` (JSON text of ``summary``).
    ``.csv``: header ``t,x,y,z,step``, ``t`` in seconds with 6 decimals (exact for
    µs stamps), ``z`` in metres (shortest round-tripping text); no metadata.
    """
    path = Path(path)
    if not isinstance(depth, np.ndarray) or depth.dtype != DEPTH_DTYPE:
        raise TypeError(f"depth must be an array of dtype {DEPTH_DTYPE}, got {getattr(depth, 'dtype', type(depth))}")
    if path.suffix not in (".npz", ".csv"):
        raise DataError(located(path, None, "depth output must be a .npz or .csv file"))
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".npz":
        try:
            summary_json = json.dumps(summary or {}, default=_jsonable)
        except (TypeError, ValueError) as err:
            raise DataError(located(path, None, f"summary is not JSON-serialisable: {err}")) from None
        np.savez(path, t=depth["t"] * 1e-6, t_us=depth["t"].astype(np.int64), x=depth["x"].astype(np.uint16),
                 y=depth["y"].astype(np.uint16), z=depth["z"].astype(np.float64), step=depth["step"].astype(np.int64),
                 t0_us=np.int64(t0_us), timestep_us=np.int64(timestep_us), latency_steps=np.int64(latency_steps),
                 summary_json=np.str_(summary_json))
        return
    rows = [f"{_seconds(t)},{x},{y},{z!r},{s}" for t, x, y, z, s in
            zip(depth["t"].tolist(), depth["x"].tolist(), depth["y"].tolist(), depth["z"].tolist(),
                depth["step"].tolist())]
    path.write_text("\n".join([CSV_HEADER, *rows]) + "\n", encoding="utf-8")


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
    if path.suffix == ".npz":
        return _read_npz(path)
    if path.suffix == ".csv":
        return _read_csv(path), {**{key: None for key in _META}, "summary": None}
    raise DataError(located(path, None, "expected a .npz or .csv depth file"))


def _read_npz(path: Path) -> tuple[np.ndarray, dict]:
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise DataError(located(path, None, "file not found")) from None
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, AttributeError) as err:
        raise DataError(located(path, None, f"not a readable .npz depth file ({err})")) from None
    missing = [key for key in ("t", "x", "y", "z", "step") if key not in arrays]
    if missing:
        raise DataError(located(path, None, f"missing array(s) {', '.join(missing)}; expected t, x, y, z, step"))
    n = arrays["t"].shape[0]
    for key in ("x", "y", "z", "step", "t_us"):
        if key in arrays and arrays[key].shape != (n,):
            raise DataError(located(path, None, f"array '{key}' has shape {arrays[key].shape}, expected ({n},) like 't'"))
    depth = np.empty(n, dtype=DEPTH_DTYPE)
    if "t_us" in arrays:
        depth["t"] = arrays["t_us"]
    else:
        depth["t"] = np.round(arrays["t"].astype(np.float64) * 1e6)
    for key in ("x", "y", "z", "step"):
        depth[key] = arrays[key]
    meta: dict[str, Any] = {key: int(arrays[key]) if key in arrays else None for key in _META}
    text = str(arrays["summary_json"]) if "summary_json" in arrays else ""
    try:
        meta["summary"] = json.loads(text) if text.strip() else {}
    except json.JSONDecodeError as err:
        raise DataError(located(path, None, f"summary_json is not valid JSON ({err.msg})")) from None
    return depth, meta


def _read_csv(path: Path) -> np.ndarray:
    text = read_text(path)
    lines = text.splitlines()
    if not lines or lines[0].strip().replace(" ", "") != CSV_HEADER:
        first = lines[0].strip() if lines else ""
        raise DataError(located(path, 1, f"expected the header '{CSV_HEADER}', got {first!r}"))
    if not any(line.strip() for line in lines[1:]):
        return np.empty(0, dtype=DEPTH_DTYPE)
    try:
        table = np.loadtxt(lines[1:], delimiter=",", dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        _raise_first_bad_row(path, lines)
        raise DataError(located(path, None, f"cannot parse the rows as '{CSV_HEADER}'")) from None
    if table.shape[1] != 5:
        _raise_first_bad_row(path, lines)
    for column, name in ((1, "x"), (2, "y"), (4, "step")):
        values = table[:, column]
        bad = np.flatnonzero((values != np.round(values)) | (values < 0) | ((values > 65535) & (column < 4)))
        if bad.size:
            raise DataError(located(path, _line_of_row(lines, int(bad[0])),
                                    f"column '{name}': expected a whole number >= 0, got {values[bad[0]]:g}"))
    depth = np.empty(table.shape[0], dtype=DEPTH_DTYPE)
    depth["t"] = np.round(table[:, 0] * 1e6)
    depth["x"], depth["y"], depth["z"], depth["step"] = table[:, 1], table[:, 2], table[:, 3], table[:, 4]
    return depth


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
                raise DataError(located(path, number, f"column '{name}': expected a number, got {field.strip()!r}")) from None
