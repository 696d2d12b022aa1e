"""Numpy event arrays as people have them (``.npy``/``.npz`` read into ``EVENT_DTYPE``, written
back): column orders, polarity names, dataset keys, metadata.

- A plain ``(n, 4)`` array has columns ``t x y p`` unless ``columns`` says otherwise
  (``"x,y,t,p"`` for MVSEC-style arrays, whose ``t`` is seconds).
- The polarity field or key may be called ``p`` (tonic, Metavision), ``on`` (faery, aedat) or
  ``polarity`` (dv-processing); the time field or key ``t`` or ``timestamp`` (dv-processing), in µs.
- ``.npz`` keys tried in order: ``events``, ``event_data`` (N-ImageNet), then four arrays.
- A ``.npz`` written by ``tofnet convert`` also holds the camera: ``intrinsics``
  (fx fy cx cy), ``distortion``, ``distortion_model``, ``sensor_size``, ``poses``
  (rows t px py pz qx qy qz qw), ``imu`` (rows t ax ay az gx gy gz).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, quote
from tofnet.events import EVENT_DTYPE, MAX_TIME_US, polarity_problem
from tofnet.io.calibration import check_intrinsics
from tofnet.io.npy import load_npy, load_npz, numpy_kind, write_npy, write_npz

COLUMNS = ("t", "x", "y", "p")
MAX_COORD = 65535  # uint16
#: Accepted names of the polarity field, in the order they are looked for.
POLARITY_NAMES = ("p", "on", "polarity")
#: Accepted names of the time field (µs), in the order they are looked for.
TIME_NAMES = ("t", "timestamp")
#: ``.npz`` keys that hold a whole structured event array.
ARRAY_KEYS = ("events", "event_data")


def parse_columns(columns: str | tuple[str, ...] | list[str] | None, source: object = "--columns") -> tuple[str, ...]:
    """``"x,y,t,p"`` (or a sequence) as a tuple: a permutation of ``t``, ``x``, ``y``, ``p``."""
    if columns is None:
        return COLUMNS
    names = tuple(str(c).strip() for c in (columns.split(",") if isinstance(columns, str) else columns))
    if sorted(names) != sorted(COLUMNS):
        raise DataError(located(source, None, f"columns must name t, x, y and p once each (e.g. x,y,t,p), "
                                              f"got {quote(','.join(names))}"))
    return names


class PlainColumns(dict):
    """Columns cut from a plain ``(n, 4)`` array (their order is an assumption worth naming in errors)."""


def _polarity_name(names) -> str | None:
    return next((name for name in POLARITY_NAMES if name in names), None)


def _time_name(names) -> str | None:
    return next((name for name in TIME_NAMES if name in names), None)


def columns_of(path: object, array: np.ndarray, what: str,
               columns: str | tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The ``t x y p`` columns of a structured array (any polarity name) or a plain ``(n, 4)`` array."""
    if array.dtype.names:
        names = array.dtype.names
        polarity, time = _polarity_name(names), _time_name(names)
        missing = (([] if time else ["t"]) + [name for name in ("x", "y") if name not in names]
                   + ([] if polarity else ["p"]))
        if missing:
            raise DataError(located(path, None, f"{what} has fields {_names(names)}; expected t (or timestamp), "
                                                f"x, y and p (or on, polarity); missing {', '.join(missing)}"))
        return {"t": array[time], "x": array["x"], "y": array["y"], "p": array[polarity]}
    if array.ndim == 2 and array.shape[1] == 4:
        order = parse_columns(columns)
        return PlainColumns((name, array[:, k]) for k, name in enumerate(order))
    raise DataError(located(path, None, f"{what} has shape {_shape(array)} and dtype {quote(str(array.dtype))}; expected a "
                                        "structured array with fields t, x, y, p or an (n, 4) array of columns "
                                        "t x y p (another order: --columns)"))


def _names(names) -> str:
    """Field or key names of a user's file for a message: each cut to 20 characters, ten at most."""
    names = list(names)
    text = ", ".join(quote(name, 20) for name in names[:10])
    return text + (f" (and {len(names) - 10} more)" if len(names) > 10 else "")


def _shape(array: np.ndarray) -> str:
    return quote(array.shape, 40)


def npz_columns(path: object, columns: str | tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The event columns of a ``.npz``: a structured array under a known key, or four arrays.

    Only the arrays needed are read, through ``tofnet.io.npy`` (sizes checked before
    anything is allocated, zip bombs and bad CRCs refused).
    """
    keys, _ = load_npz(path, (), "events file")
    for key in ARRAY_KEYS:
        if key in keys:
            _, arrays = load_npz(path, (key,), "events file")
            return columns_of(path, arrays[key], f"'{key}'", columns)
    polarity, time = _polarity_name(keys), _time_name(keys)
    if polarity and time and {"x", "y"} <= set(keys):
        _, arrays = load_npz(path, (time, "x", "y", polarity), "events file")
        return {"t": arrays[time], "x": arrays["x"], "y": arrays["y"], "p": arrays[polarity]}
    raise DataError(located(path, None, f"expected a structured array 'events' or arrays 't', 'x', 'y', 'p' "
                                        f"(or N-ImageNet's 'event_data'); found {_names(keys) or 'nothing'}"))


def npz_unread(path: object, keys: list[str]) -> list[str]:
    """The arrays of an events ``.npz`` (its ``keys``) that neither ``npz_columns`` nor ``apply_npz_metadata`` reads."""
    used = set(METADATA_KEYS)
    event_key = next((key for key in ARRAY_KEYS if key in keys), None)
    used |= {event_key} if event_key else {_time_name(keys), _polarity_name(keys), "x", "y"}
    return [key for key in keys if key not in used]


#: The camera metadata keys ``write_npz_recording`` adds beside the events.
METADATA_KEYS = ("intrinsics", "distortion", "distortion_model", "sensor_size", "poses", "imu")


def apply_npz_metadata(recording, path: Path) -> None:
    """Set what a ``tofnet convert`` ``.npz`` holds besides events (the file wins over side files).

    Each array is checked (shape, finite numbers); the sensor size, intrinsics and IMU
    then go through the checks every reader shares (``tofnet.io.source``).
    """
    from tofnet.io.groundtruth import Trajectory
    from tofnet.io.recording import Intrinsics

    _, arrays = load_npz(path, METADATA_KEYS, "events file")

    def numbers(key: str, shape: str, columns: int | None = None) -> np.ndarray:
        array = arrays[key]
        ok = array.dtype.kind in "iuf" and (array.ndim == 1 if columns is None else
                                            (array.ndim == 2 and array.shape[1] == columns))
        if ok:
            array = array.astype(np.float64)
            ok = bool(np.all(np.isfinite(array)))
        if not ok:
            raise DataError(located(f"{path}[{key}]", None, f"expected finite numbers of shape {shape}, got shape "
                                                            f"{_shape(arrays[key])} and dtype {quote(str(arrays[key].dtype))}"))
        return array

    if "intrinsics" in arrays:
        values = numbers("intrinsics", "(4,)")
        if values.shape != (4,):
            raise DataError(located(f"{path}[intrinsics]", None, f"expected 4 numbers fx fy cx cy, got {len(values)}"))
        distortion = tuple(float(v) for v in numbers("distortion", "(n,)")) if "distortion" in arrays else ()
        model = "radtan"
        if "distortion_model" in arrays:
            raw = arrays["distortion_model"]
            if raw.dtype.kind != "U" or raw.ndim != 0 or str(raw) not in ("radtan", "equidistant"):
                raise DataError(located(f"{path}[distortion_model]", None, "expected 'radtan' or 'equidistant'"))
            model = str(raw)
        fx, fy, cx, cy = (float(v) for v in values)
        try:
            check_intrinsics(fx, fy, cx, cy)
        except ValueError as err:
            raise DataError(located(f"{path}[intrinsics]", None, str(err))) from None
        recording.intrinsics = Intrinsics(fx, fy, cx, cy, distortion=distortion, distortion_model=model)
    if "sensor_size" in arrays:
        size = numbers("sensor_size", "(2,)")
        if size.shape != (2,) or np.any(size != np.floor(size)) or np.any(np.abs(size) > 2**31):
            raise DataError(located(f"{path}[sensor_size]", None, "expected two whole numbers width, height"))
        recording.sensor_size = (int(size[0]), int(size[1]))
    if "poses" in arrays:
        poses = numbers("poses", "(n, 8)", 8)
        recording.trajectory = Trajectory(poses[:, 0], poses[:, 1:4], poses[:, 4:8], source=f"{path}[poses]")
    if "imu" in arrays:
        recording.imu = numbers("imu", "(n, 7)", 7)


def write_npz_recording(path: str | Path, recording) -> None:
    """Events (``t`` int64 µs, ``x``, ``y`` uint16, ``p`` uint8) and the camera metadata in one ``.npz``
    (written atomically)."""
    events = recording.events
    arrays = {name: np.ascontiguousarray(events[name]) for name in COLUMNS}
    intrinsics = recording.intrinsics
    if intrinsics is not None:
        arrays["intrinsics"] = np.array([intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy])
        arrays["distortion"] = np.asarray(intrinsics.distortion, dtype=np.float64)
        arrays["distortion_model"] = np.array(intrinsics.distortion_model)
    if recording.sensor_size is not None:
        arrays["sensor_size"] = np.asarray(recording.sensor_size, dtype=np.int64)
    trajectory = recording.trajectory
    if trajectory is not None and hasattr(trajectory, "quaternions"):
        arrays["poses"] = np.column_stack([trajectory.times, trajectory.positions, trajectory.quaternions])
    if recording.imu is not None:
        arrays["imu"] = np.asarray(recording.imu, dtype=np.float64)
    write_npz(path, arrays)


def check_writable(events: np.ndarray) -> np.ndarray:
    """``events`` when it is an ``EVENT_DTYPE`` array with polarities 0/1 (what the writers take)."""
    if not isinstance(events, np.ndarray) or events.dtype != EVENT_DTYPE:
        raise TypeError(f"events must be an array of dtype {EVENT_DTYPE}, got {getattr(events, 'dtype', type(events))}")
    problem = polarity_problem(events["p"])
    if problem:
        raise DataError(problem)
    return events


def read_events_npy(path: str | Path, columns: str | tuple[str, ...] | None = None) -> np.ndarray:
    """Read events from ``.npy`` or ``.npz`` into ``EVENT_DTYPE`` (t in µs).

    ``.npy``: a structured array with fields ``t x y p``, or an ``(n, 4)`` array of
    columns ``t x y p`` (another order: ``columns="x,y,t,p"``). ``.npz``: a structured
    array under key ``events`` or ``event_data``, or arrays ``t``, ``x``, ``y``, ``p``.
    The polarity may be named ``p``, ``on`` or ``polarity`` (``tofnet.io.arrays``).
    A float ``t`` is seconds, an integer ``t`` microseconds.
    Polarity -1 maps to 0 (OFF); booleans are accepted.
    """
    path = Path(path)
    if numpy_kind(path, "events file") == "npz":
        arrays = npz_columns(path, columns)
    else:
        arrays = columns_of(path, load_npy(path, "events file"), "the array", columns)
    try:
        return events_from_columns(arrays, path)
    except DataError as err:
        if columns is None and isinstance(arrays, PlainColumns):
            raise DataError(f"{err} (a plain (n, 4) array is read as columns t x y p; "
                            "for another order pass --columns, e.g. x,y,t,p)") from None
        raise


def seconds_to_us(t: np.ndarray) -> np.ndarray:
    """Float seconds to float64 µs rounded to the nearest whole µs, halves away from zero (via float64)."""
    scaled = np.asarray(t).astype(np.float64) * 1e6
    return np.sign(scaled) * np.floor(np.abs(scaled) + 0.5)


#: A float time column whose precision at its largest time is coarser than this (s) is refused.
MAX_FLOAT_STEP_S = 1e-3


def float_time_step(t: np.ndarray) -> float:
    """The step (s) between neighbouring values of a float32/float16 time column at its largest magnitude; 0 for
    float64 and integers (which hold µs exactly where tofnet accepts times)."""
    t = np.asarray(t)
    if t.dtype.kind != "f" or t.dtype.itemsize >= 8 or t.size == 0:
        return 0.0
    return float(np.spacing(np.max(np.abs(t)).astype(t.dtype)))


def times_us_for_search(t: np.ndarray) -> np.ndarray:
    """A slice of a ``t`` column as the µs ``events_from_columns`` makes of it, for binary searches
    (float seconds rounded; integers as they are, unsigned ones beyond int64 clipped: refused later)."""
    if t.dtype.kind == "f":
        return seconds_to_us(t)
    if t.dtype.kind == "u":
        return np.minimum(t, np.iinfo(np.int64).max).astype(np.int64)
    return np.asarray(t).astype(np.int64)


def read_npy_window(path: str | Path, columns, window) -> tuple[np.ndarray, int, int, int, int]:
    """The events of a ``.npy`` file in ``window`` (``tofnet.io.window.TimeWindow``), reading only
    their rows (a memory map and a binary search on the sorted ``t``): ``(events, first event µs,
    first row, end row, last event µs)``. Events outside the window are not checked."""
    from tofnet.io.npy import map_npy
    from tofnet.io.window import first_at_or_after

    path = Path(path)
    cols = columns_of(path, map_npy(path, "events file"), "the array", columns)
    n = len(cols["t"])
    if n == 0:
        raise DataError(located(path, None, "no events"))

    def times(lo: int, hi: int) -> np.ndarray:
        return times_us_for_search(np.asarray(cols["t"][lo:hi]))

    first, last = int(times(0, 1)[0]), int(times(n - 1, n)[0])
    start, stop = window.resolve(first)
    lo = first_at_or_after(times, n, start)
    hi = n if stop is None else max(first_at_or_after(times, n, stop), lo)
    if hi == lo:  # the source says which window and where the recording ends
        return np.empty(0, dtype=EVENT_DTYPE), first, lo, hi, last
    events = events_from_columns({name: np.asarray(col[lo:hi]) for name, col in cols.items()},
                                 f"{path} (rows {lo}..{hi - 1})")
    return events, first, lo, hi, last


def events_from_columns(columns: dict[str, np.ndarray], source: object = "<memory>") -> np.ndarray:
    """Validate columns ``t x y p`` and build an ``EVENT_DTYPE`` array.

    Float ``t`` is seconds (rounded to the nearest µs, half away from zero), integer
    ``t`` microseconds. Errors name the field and the (0-based) event index.
    """
    arrays = {name: np.asarray(columns[name]) for name in COLUMNS}
    lengths = {name: a.shape for name, a in arrays.items()}
    n = arrays["t"].shape[0] if arrays["t"].ndim == 1 else -1
    if any(a.shape != (n,) for a in arrays.values()):
        raise DataError(located(source, None, f"t, x, y, p must be 1-D arrays of one length, got shapes {lengths}"))
    if n == 0:
        raise DataError(located(source, None, "no events (the arrays are empty)"))

    def fail(name: str, index: int, message: str) -> DataError:
        return DataError(located(source, None, f"field '{name}', event {index}: {message}"))

    for name, a in arrays.items():
        if a.dtype.kind not in ("iuf" if name != "p" else "biuf"):
            raise DataError(located(source, None, f"field '{name}': expected numbers, got dtype {a.dtype}"))
        if a.dtype.kind == "f":
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise fail(name, int(bad[0]), f"expected a finite number, got {a[bad[0]]}")
    t = arrays["t"]
    limit = MAX_TIME_US
    step = float_time_step(t)
    if step > MAX_FLOAT_STEP_S:
        raise DataError(located(source, None, f"field 't': {t.dtype} seconds step by {step:g} s at "
                                              f"{float(np.max(np.abs(t))):g} s, coarser than a 1 ms step: the times "
                                              "are lost; store seconds as float64 or µs as integers"))
    if t.dtype.kind == "f":
        t_us = seconds_to_us(t)
        bad = np.flatnonzero(np.abs(t_us) >= limit)
        if bad.size:
            raise fail("t", int(bad[0]), f"{t[bad[0]]:g} s is out of range (|t| < 2**61 µs; float t is seconds)")
        t_us = t_us.astype(np.int64)
    else:
        # Compare in the file's own dtype: uint64 >= 2**63 must not wrap to negative first.
        bad = np.flatnonzero((t >= limit) | (t <= -limit)) if t.dtype.kind == "i" else np.flatnonzero(t >= limit)
        if bad.size:
            raise fail("t", int(bad[0]), f"{t[bad[0]]} µs is out of range (|t| < 2**61 µs; integer t is microseconds)")
        t_us = t.astype(np.int64)
    # In range, a difference of two times cannot overflow int64.
    back = np.flatnonzero(np.diff(t_us) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise fail("t", i, f"time goes back ({t_us[i]} µs after {t_us[i - 1]} µs); events must be sorted by time")
    for name in ("x", "y"):
        a = arrays[name] if arrays[name].dtype.kind != "f" else arrays[name].astype(np.float64)
        checks = [(a < 0, "pixel coordinates must be >= 0"), (a > MAX_COORD, f"expected at most {MAX_COORD}")]
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
    events = check_writable(events)
    path = Path(path)
    if path.suffix == ".npy":
        write_npy(path, events)
    elif path.suffix == ".npz":
        write_npz(path, {name: np.ascontiguousarray(events[name]) for name in COLUMNS})
    else:
        raise DataError(located(path, None, "expected a .npy or .npz file name"))
