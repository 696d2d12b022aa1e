"""HDF5 event files through h5py: the DSEC/TUM-VIE layout (also what tofnet writes), MVSEC, M3ED.

The layout is recognised from the datasets present:

- ``events/{x,y,t,p}`` (DSEC, TUM-VIE, tofnet): ``t`` µs relative to the scalar
  ``t_offset`` (0 when absent); ``ms_to_idx`` is not needed to read. tofnet adds
  ``calib/{intrinsics,distortion_coeffs,distortion_model,resolution}``,
  ``poses/{t,position,quaternion}`` and ``imu/{t,accel,gyro}``; DSEC's
  ``calibration/cam_to_cam.yaml`` (``cam0`` left, ``cam3`` right) is read when found.
- ``davis/left/events`` (MVSEC): ``(n, 4)`` rows ``x, y, t [s], p [-1/1]``; IMU from
  ``davis/left/imu``; poses and depth from the ``*_gt.hdf5`` file next to it.
- ``prophesee/left/{x,y,t,p}`` (M3ED): ``t`` µs; calibration from ``prophesee/left/calib``;
  poses and depth from ``*_depth_gt.h5`` (or ``*_pose_gt.h5``) next to it.

Compressed datasets with a filter h5py lacks (Blosc, Zstandard, ...) need ``hdf5plugin``.
Every dataset is reached through ``tofnet.io.hdf5_checks.H5File``: external storage,
virtual datasets and external links are refused unless ``allow_external``, and declared
sizes are checked against the storage the file holds before anything is read.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.events import MAX_TIME_US
from tofnet.io.extras import require
from tofnet.io.hdf5_checks import H5File
from tofnet.io.recording import Intrinsics
from tofnet.io.calibration import intrinsics_from
from tofnet.io.event_source import FIRST_TIMES, EventSource


def scalar(h5: H5File, name: str, default=None):
    """A scalar or small dataset as a Python/numpy value, ``default`` when absent."""
    return h5.value(name, default)


class ColumnsSource(EventSource):
    """Events in four 1-D datasets (``x``, ``y``, ``t`` µs, ``p``) plus a time offset in µs."""

    format = "hdf5"

    def __init__(self, path: Path, h5: H5File, group: str, t_offset: int = 0):
        super().__init__(path)
        self.h5, self.handle = h5, h5.handle
        self.columns = {name: h5.dataset(f"{group}/{name}") for name in ("t", "x", "y", "p")}
        lengths = {name: d.shape for name, d in self.columns.items()}
        if len({shape for shape in lengths.values()}) != 1 or len(lengths["t"]) != 1:
            raise DataError(located(path, None, f"{group}/{{t,x,y,p}} must be 1-D of one length, got {lengths}"))
        if self.columns["t"].dtype.kind not in "iu":
            raise DataError(located(path, None, f"{group}/t: expected integer microseconds, "
                                                f"got {self.columns['t'].dtype}"))
        self.n_events = self.n_rows = int(lengths["t"][0])  # n_events becomes the window's count
        self.t_offset = int(t_offset)
        if abs(self.t_offset) >= MAX_TIME_US:
            raise DataError(located(path, None, f"t_offset {self.t_offset} µs is out of range (|t| < 2**61 µs)"))

    #: The file's millisecond index (``ms_to_idx``; M3ED's ``ms_map_idx``), a dataset or None.
    ms_index = None

    def _packets(self, size_hint: int) -> Iterable[np.ndarray]:
        return self._rows(0, self.n_rows, size_hint)

    def _times(self, lo: int, hi: int) -> np.ndarray:
        """Event times ``lo..hi-1`` in µs on the file's clock."""
        return self.columns["t"][lo:hi].astype(np.int64) + self.t_offset

    def first_time(self) -> int | None:
        return int(self._times(0, 1)[0]) if self.n_rows else None

    def first_times(self, count: int = FIRST_TIMES) -> np.ndarray:
        return self._times(0, min(count, FIRST_TIMES, self.n_rows))  # the time column's first rows only

    def _window_end_us(self) -> int | None:
        return int(self._times(self.n_rows - 1, self.n_rows)[0]) if self.n_rows else None

    def last_time(self) -> int | None:
        return self._window_end_us()  # known without decoding

    def _index_at(self, us: int) -> int:
        """The first event at or after ``us``: the ms index narrows it, a binary search finds it."""
        from tofnet.io.window import first_at_or_after

        bracket = None
        k = (us - self.t_offset) // 1000 if self.ms_index is not None else -1
        if self.ms_index is not None and 0 <= k < self.ms_index.shape[0]:
            pair = self.ms_index[k:k + 2]
            bracket = (int(pair[0]), int(pair[1]) if len(pair) > 1 else self.n_rows)
        return first_at_or_after(self._times, self.n_rows, us, bracket)

    def _window_range(self, start: int, stop: int | None) -> tuple[int, int]:
        lo = self._index_at(start)
        return lo, self.n_rows if stop is None else max(self._index_at(stop), lo)

    def _window_count(self, start: int, stop: int | None) -> int | None:
        lo, hi = self._window_range(start, stop)
        return hi - lo

    def _window_packets(self, size_hint: int, start: int, stop: int | None) -> Iterable[np.ndarray]:
        # Only the window's rows are read (a 10 s window of a 20 GB file reads about 10 s of it).
        lo, hi = self._window_range(start, stop)
        self._first_index = lo
        return self._rows(lo, hi, size_hint)

    def _rows(self, first: int, last: int, size_hint: int) -> Iterable[np.ndarray]:
        from tofnet.io.events import events_from_columns

        for start in range(first, last, size_hint):
            stop = min(start + size_hint, last)
            arrays = {name: dataset[start:stop] for name, dataset in self.columns.items()}
            t = arrays["t"]
            # In range before the cast and the sum, so neither wraps (uint64 past 2**63).
            outside = np.flatnonzero((t >= MAX_TIME_US) | ((t <= -MAX_TIME_US) if t.dtype.kind == "i" else False))
            if outside.size:
                i = int(outside[0])
                raise DataError(located(self.path, None, f"event {start + i + 1:,}: t = {int(t[i])} µs is out of "
                                                         "range (|t| < 2**61 µs)"))
            arrays["t"] = t.astype(np.int64) + self.t_offset
            yield events_from_columns(arrays, f"{self.path} (events {start}..{stop - 1})")

    def close(self) -> None:
        self.handle.close()


class DsecSource(ColumnsSource):
    """DSEC / TUM-VIE ``events/{x,y,t,p}`` + ``t_offset``, and what tofnet adds (see the module docstring)."""

    def __init__(self, path: Path, h5: H5File):
        super().__init__(path, h5, "events", t_offset=_t_offset(h5))
        self.detail = "DSEC layout"
        if "ms_to_idx" in h5 and h5.dataset("ms_to_idx").ndim == 1:
            self.ms_index = h5.dataset("ms_to_idx")
            self.streams["ms_to_idx"] = f"{self.ms_index.shape[0]} ms index entries (used for time windows)"
        self.intrinsics, self.sensor_size = read_calib_group(h5, "calib", path)
        if "poses" in h5:
            from tofnet.io.groundtruth import Trajectory
            t, position, quaternion = _group(h5, "poses", ("t", "position", "quaternion"), path)
            self.trajectory = Trajectory(t, position, quaternion, source=f"{path}:poses")
        if "imu" in h5:
            t, accel, gyro = _group(h5, "imu", ("t", "accel", "gyro"), path)
            if not len(t) == len(accel) == len(gyro):
                raise DataError(located(path, None, f"imu: t, accel and gyro hold {len(t)}, {len(accel)} and "
                                                    f"{len(gyro)} samples; expected one count"))
            self.imu = np.column_stack([t, accel, gyro])
        if self.intrinsics is None:
            self._dsec_calibration()
        for key in sorted(set(h5.keys()) - {"events", "ms_to_idx", "t_offset", "calib", "poses", "imu"}):
            self.not_read(key)

    def _dsec_calibration(self) -> None:
        # DSEC: <sequence>/events/{left,right}/events.h5 and <sequence>/calibration/cam_to_cam.yaml.
        side = self.path.parent.name
        yaml_path = self.path.parent.parent.parent / "calibration" / "cam_to_cam.yaml"
        if side not in ("left", "right") or not (yaml_path.exists() or yaml_path.is_symlink()):
            return
        from tofnet.io.calibration import read_camera_file  # the one reader of cam_to_cam.yaml (--calib too)
        self.intrinsics, size, _ = read_camera_file(yaml_path, "cam0" if side == "left" else "cam3")
        self.sensor_size = self.sensor_size or size
        self.notes.append(f"intrinsics from {yaml_path}")


def read_calib_group(h5: H5File, group: str, path: object) -> tuple[Intrinsics | None, tuple[int, int] | None]:
    """``{group}/{intrinsics,distortion_coeffs,distortion_model,resolution}`` (M3ED, tofnet)."""
    size = _resolution(scalar(h5, f"{group}/resolution"), f"{group}/resolution", path)
    if f"{group}/intrinsics" not in h5:
        return None, size
    try:
        intrinsics = intrinsics_from(h5.value(f"{group}/intrinsics"), scalar(h5, f"{group}/distortion_coeffs", ()),
                                     scalar(h5, f"{group}/distortion_model", "radtan"))
    except ValueError as err:
        raise DataError(located(path, None, f"{group}: {err}")) from None
    return intrinsics, size


def _resolution(value, name: str, path: object) -> tuple[int, int] | None:
    if value is None:
        return None
    values = np.ravel(np.asarray(value))
    if values.size != 2 or values.dtype.kind not in "iuf" or not np.all(np.isfinite(values)) \
            or np.any(values != np.floor(values)):
        raise DataError(located(path, None, f"{name}: expected two whole numbers (width, height) in pixels, got "
                                            f"{values.dtype} of shape {np.shape(value)}"))
    return int(values[0]), int(values[1])


def _group(h5: H5File, group: str, names: tuple[str, ...], path: object) -> list:
    """The datasets ``group/name`` for each of ``names``; a missing one is one line naming it."""
    for name in names:
        if f"{group}/{name}" not in h5:
            raise DataError(located(path, None, f"{group}/{name}: missing ({group} needs {', '.join(names)})"))
    return [h5.value(f"{group}/{name}") for name in names]


def _t_offset(h5: H5File) -> int:
    """DSEC's scalar ``t_offset`` (µs), 0 when absent; one whole number."""
    value = np.asarray(h5.value("t_offset", 0))
    if value.size != 1 or value.dtype.kind not in "iu":
        raise DataError(located(h5.path, None, f"t_offset: expected one whole number of µs, got {value.dtype} "
                                               f"of shape {value.shape}"))
    if abs(int(value.reshape(-1)[0])) >= MAX_TIME_US:
        raise DataError(located(h5.path, None, f"t_offset {int(value.reshape(-1)[0])} µs is out of range "
                                               "(|t| < 2**61 µs)"))
    return int(value.reshape(-1)[0])


def write_hdf5(path: str | Path, chunks: Iterable[np.ndarray], meta) -> int:
    """Write events in the DSEC layout (plus tofnet's calib/poses/imu groups); returns the event count.

    ``events/t`` is int64 µs after ``t_offset`` (the first event's time), ``x``, ``y``
    uint16, ``p`` uint8; ``ms_to_idx[k]`` is the index of the first event at or after
    ``t_offset + k`` ms. Chunks are appended as they come (bounded memory). ``meta``
    (a ``Recording`` or ``EventSource``) gives sensor size, intrinsics, poses and IMU,
    read after the events.
    """
    h5py = require("h5py", path)
    written, next_ms, t_offset = 0, 0, None
    from tofnet.io.lenient_file import LenientFile

    # Through LenientFile: a failed write (a full disk) is raised once libhdf5 has closed
    # the file; raised inside libhdf5 it crashes the interpreter later (SIGSEGV).
    with LenientFile(path) as handle, h5py.File(handle, "w") as out:
        columns = {name: out.create_dataset(f"events/{name}", shape=(0,), maxshape=(None,), dtype=dtype,
                                            chunks=(1 << 16,))
                   for name, dtype in (("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1"))}
        ms_to_idx = out.create_dataset("ms_to_idx", shape=(0,), maxshape=(None,), dtype="<u8", chunks=(1 << 12,))
        for chunk in chunks:
            if handle.error is not None:
                break  # nothing more can be written; raised once closed
            if len(chunk) == 0:
                continue
            if t_offset is None:
                t_offset = int(chunk["t"][0])
            relative = chunk["t"] - t_offset
            for name, dataset in columns.items():
                dataset.resize((written + len(chunk),))
                dataset[written:] = relative if name == "t" else chunk[name]
            last_ms = int(relative[-1]) // 1000
            if last_ms >= next_ms:
                bounds = np.arange(next_ms, last_ms + 1, dtype=np.int64) * 1000
                _append(ms_to_idx, written + np.searchsorted(relative, bounds, side="left"))
                next_ms = last_ms + 1
            written += len(chunk)
        _append(ms_to_idx, np.array([written]))
        out.create_dataset("t_offset", data=np.int64(t_offset or 0))
        sensor_size, intrinsics, trajectory, imu = meta.sensor_size, meta.intrinsics, meta.trajectory, meta.imu
        if sensor_size is not None:
            out.create_dataset("calib/resolution", data=np.asarray(sensor_size, dtype=np.int64))
        if intrinsics is not None:
            out.create_dataset("calib/intrinsics", data=np.array([intrinsics.fx, intrinsics.fy, intrinsics.cx,
                                                                  intrinsics.cy]))
            out.create_dataset("calib/distortion_coeffs", data=np.asarray(intrinsics.distortion, dtype=np.float64))
            out.create_dataset("calib/distortion_model", data=intrinsics.distortion_model)
        if trajectory is not None and hasattr(trajectory, "quaternions"):
            out.create_dataset("poses/t", data=trajectory.times)
            out.create_dataset("poses/position", data=trajectory.positions)
            out.create_dataset("poses/quaternion", data=trajectory.quaternions)
        if imu is not None and len(imu):
            out.create_dataset("imu/t", data=imu[:, 0])
            out.create_dataset("imu/accel", data=imu[:, 1:4])
            out.create_dataset("imu/gyro", data=imu[:, 4:7])
    return written


def _append(dataset, values: np.ndarray) -> None:
    start = dataset.shape[0]
    dataset.resize((start + len(values),))
    dataset[start:] = values
