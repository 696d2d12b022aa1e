"""Numpy event arrays as people have them: column orders, polarity names, dataset keys, metadata.

- A plain ``(n, 4)`` array has columns ``t x y p`` unless ``columns`` says otherwise
  (``"x,y,t,p"`` for MVSEC-style arrays, whose ``t`` is seconds).
- The polarity field or key may be called ``p``, ``on`` (faery, aedat) or ``polarity``.
- ``.npz`` keys tried in order: ``events``, ``event_data`` (N-ImageNet), then four arrays.
- A ``.npz`` written by ``tofnet convert`` also holds the camera: ``intrinsics``
  (fx fy cx cy), ``distortion``, ``distortion_model``, ``sensor_size``, ``poses``
  (rows t px py pz qx qy qz qw), ``imu`` (rows t ax ay az gx gy gz).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located

COLUMNS = ("t", "x", "y", "p")
#: Accepted names of the polarity field, in the order they are looked for.
POLARITY_NAMES = ("p", "on", "polarity")
#: ``.npz`` keys that hold a whole structured event array.
ARRAY_KEYS = ("events", "event_data")


def parse_columns(columns: str | tuple[str, ...] | list[str] | None, source: object = "--columns") -> tuple[str, ...]:
    """``"x,y,t,p"`` (or a sequence) as a tuple: a permutation of ``t``, ``x``, ``y``, ``p``."""
    if columns is None:
        return COLUMNS
    names = tuple(c.strip() for c in (columns.split(",") if isinstance(columns, str) else columns))
    if sorted(names) != sorted(COLUMNS):
        raise DataError(located(source, None, f"columns must name t, x, y and p once each (e.g. x,y,t,p), "
                                              f"got {','.join(names)}"))
    return names


class PlainColumns(dict):
    """Columns cut from a plain ``(n, 4)`` array (their order is an assumption worth naming in errors)."""


def _polarity_name(names) -> str | None:
    return next((name for name in POLARITY_NAMES if name in names), None)


def columns_of(path: object, array: np.ndarray, what: str,
               columns: str | tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The ``t x y p`` columns of a structured array (any polarity name) or a plain ``(n, 4)`` array."""
    if array.dtype.names:
        names = array.dtype.names
        polarity = _polarity_name(names)
        missing = [name for name in ("t", "x", "y") if name not in names] + ([] if polarity else ["p"])
        if missing:
            raise DataError(located(path, None, f"{what} has fields {', '.join(names)}; expected t, x, y and "
                                                f"p (or on, polarity); missing {', '.join(missing)}"))
        return {"t": array["t"], "x": array["x"], "y": array["y"], "p": array[polarity]}
    if array.ndim == 2 and array.shape[1] == 4:
        order = parse_columns(columns)
        return PlainColumns((name, array[:, k]) for k, name in enumerate(order))
    raise DataError(located(path, None, f"{what} has shape {array.shape} and dtype {array.dtype}; expected a "
                                        "structured array with fields t, x, y, p or an (n, 4) array of columns "
                                        "t x y p (another order: --columns)"))


def npz_columns(path: object, loaded, columns: str | tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The event columns of an open ``.npz``: a structured array under a known key, or four arrays."""
    keys = list(loaded.files)
    for key in ARRAY_KEYS:
        if key in keys:
            return columns_of(path, loaded[key], f"'{key}'", columns)
    polarity = _polarity_name(keys)
    if polarity and {"t", "x", "y"} <= set(keys):
        return {"t": loaded["t"], "x": loaded["x"], "y": loaded["y"], "p": loaded[polarity]}
    raise DataError(located(path, None, f"expected a structured array 'events' or arrays 't', 'x', 'y', 'p' "
                                        f"(or N-ImageNet's 'event_data'); found {', '.join(keys) or 'nothing'}"))


def apply_npz_metadata(recording, path: Path) -> None:
    """Set what a ``tofnet convert`` ``.npz`` holds besides events (the file wins over side files)."""
    from tofnet.io.groundtruth import Trajectory
    from tofnet.io.recording import Intrinsics

    with np.load(path, allow_pickle=False) as loaded:
        keys = set(loaded.files)
        if "intrinsics" in keys:
            fx, fy, cx, cy = (float(v) for v in loaded["intrinsics"])
            distortion = tuple(float(v) for v in loaded["distortion"]) if "distortion" in keys else ()
            model = str(loaded["distortion_model"]) if "distortion_model" in keys else "radtan"
            recording.intrinsics = Intrinsics(fx, fy, cx, cy, distortion=distortion, distortion_model=model)
        if "sensor_size" in keys:
            recording.sensor_size = tuple(int(v) for v in loaded["sensor_size"])
        if "poses" in keys:
            poses = loaded["poses"]
            recording.trajectory = Trajectory(poses[:, 0], poses[:, 1:4], poses[:, 4:8], source=f"{path}:poses")
        if "imu" in keys:
            recording.imu = np.asarray(loaded["imu"], dtype=np.float64)


def write_npz_recording(path: str | Path, recording) -> None:
    """Events (``t`` int64 µs, ``x``, ``y`` uint16, ``p`` uint8) and the camera metadata in one ``.npz``."""
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
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)
