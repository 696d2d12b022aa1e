"""MVSEC and M3ED HDF5 files, with their ground truth (poses, depth images) from the companion file.

Ground-truth depth comes as images at given times (``DepthImages``, a
``tofnet.io.frames.FrameDepth``, the source's ``frame_gt``); the true depth of an event is
the value of the image nearest in time at the event's pixel (NaN where the image has 0,
NaN or inf, or when the nearest image is more than ``MAX_DEPTH_GAP_S`` away). Only the
images a chunk needs are read. The ground truth is the left camera's: with ``side="right"``
the depth images are not given to the right camera's events.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, reason
from tofnet.events import MAX_TIME_US
from tofnet.io.files import present
from tofnet.io.hdf5 import ColumnsSource, read_calib_group
from tofnet.io.frames import FrameDepth
from tofnet.io.hdf5_checks import H5File

#: An event further than this from every depth image gets no true depth (s).
MAX_DEPTH_GAP_S = 0.1


class DepthImages(FrameDepth):
    """Depth images ``(n, H, W)`` metres in an HDF5 dataset at times ``times_us`` (a ``FrameDepth``).

    The file is opened again (with the same checks) when the source that opened it has been closed:
    ``tofnet eval`` reads the frames its estimates need after the events were read."""

    def __init__(self, dataset, times_us: np.ndarray, source: Path, allow_external: bool = False):
        if dataset.ndim != 3 or dataset.shape[0] != len(times_us):
            raise DataError(located(source, None, f"depth images {dataset.shape} do not match {len(times_us)} "
                                                  "timestamps"))
        super().__init__(times_us, self._read, dataset.shape[1:], source, max_gap_s=MAX_DEPTH_GAP_S)
        self.dataset, self.name, self.allow_external = dataset, dataset.name.lstrip("/"), allow_external

    def _read(self, k: int) -> np.ndarray:
        if not self.dataset.id.valid:
            import h5py
            if not present(self.source, "the ground truth (HDF5)"):  # checked again: h5py would wait on a FIFO
                raise DataError(located(self.source, None, "missing now: the ground truth (HDF5) read when the "
                                                           "recording was opened"))
            self.dataset = H5File(h5py.File(self.source, "r"), self.source, self.allow_external).dataset(self.name)
        return self.dataset[k]

    def lookup(self, events: np.ndarray) -> np.ndarray:
        """True depth (m) of each event, NaN where unknown."""
        return self.at_events(events)


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(n, 4)`` ``qx qy qz qw`` from rotation matrices ``(n, 3, 3)`` (Shepperd)."""
    r = np.asarray(rotation, dtype=np.float64).reshape(-1, 3, 3)
    q = np.empty((r.shape[0], 4))
    trace = r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2]
    diagonal = np.stack([r[:, 0, 0], r[:, 1, 1], r[:, 2, 2], trace], axis=1)
    for n, k in enumerate(np.argmax(diagonal, axis=1)):
        m = r[n]
        if k == 3:
            s = 2.0 * np.sqrt(1.0 + trace[n])
            q[n] = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
        else:
            i, j, l = k, (k + 1) % 3, (k + 2) % 3
            s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[l, l])
            q[n, i] = s / 4
            q[n, j] = (m[j, i] + m[i, j]) / s
            q[n, l] = (m[l, i] + m[i, l]) / s
            q[n, 3] = (m[l, j] - m[j, l]) / s
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def trajectory_from_matrices(times_s: np.ndarray, camera_to_world: np.ndarray, source: object):
    """A ``Trajectory`` from 4x4 camera-to-world transforms at ``times_s``."""
    from tofnet.io.groundtruth import Trajectory

    matrices = np.asarray(camera_to_world, dtype=np.float64)
    return Trajectory(times_s, matrices[:, :3, 3], matrix_to_quaternion(matrices[:, :3, :3]), source=source)


def _companion(path: Path, stem_suffix: str, suffixes: tuple[str, ...], what: str) -> Path | None:
    """``<base><suffix>`` next to ``path`` where ``path`` is ``<base>_data.<ext>``; ``None`` when there is
    none, a one-line error when one exists but is not a regular file (``tofnet.io.files.present``)."""
    stem = path.stem[:-len("_data")] if path.stem.endswith("_data") else path.stem
    for suffix in suffixes:
        candidate = path.with_name(f"{stem}{stem_suffix}{suffix}")
        if present(candidate, what):
            return candidate
    return None


def image_times_us(h5: H5File, name: str, scale: float) -> np.ndarray:
    """Ground-truth timestamps ``name`` (``scale`` µs per unit) as int64 µs: one line naming the
    dataset unless they are finite, in the time range and strictly increasing (an image lookup
    and a trajectory both need that)."""
    values = np.asarray(h5.value(name), dtype=np.float64)
    where = f"{name}: "
    if values.ndim != 1:
        raise DataError(located(h5.path, None, f"{where}expected one timestamp per row, got shape {values.shape}"))
    bad = np.flatnonzero(~np.isfinite(values) | (np.abs(values * scale) >= MAX_TIME_US))
    if bad.size:
        i = int(bad[0])
        raise DataError(located(h5.path, None, f"{where}timestamp {i} is {values[i]!r}, expected a finite time "
                                               "(|t| < 2**61 µs)"))
    times = np.round(values * scale).astype(np.int64)
    back = np.flatnonzero(np.diff(times) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise DataError(located(h5.path, None, f"{where}timestamps must be strictly increasing, got "
                                               f"{values[i]!r} after {values[i - 1]!r} (row {i})"))
    return times


class _GroundTruthMixin:
    @contextmanager
    def _opened_gt(self, gt_path: Path) -> Iterator[H5File]:
        """The ground-truth file, kept open for the depth images (closed with the source) unless
        reading it fails."""
        import h5py

        from tofnet.io.guard import note_read
        note_read(gt_path)  # h5py opens it: protected from the command's outputs all the same
        try:
            self.gt = H5File(h5py.File(gt_path, "r"), gt_path, self.h5.allow_external)
        except OSError as err:
            raise DataError(located(gt_path, None, f"not a readable HDF5 file ({reason(err)})")) from None
        try:
            yield self.gt
        except BaseException:
            self.gt.handle.close()
            self.gt = None
            raise

    def close(self) -> None:
        gt = getattr(self, "gt", None)
        for handle in (self.handle, gt.handle if gt is not None else None):
            if handle is not None:
                handle.close()


class MvsecSource(_GroundTruthMixin, ColumnsSource):
    """MVSEC ``*_data.hdf5`` (left DAVIS) with ``*_gt.hdf5`` poses and raw depth images."""

    def __init__(self, path: Path, h5: H5File, side: str = "left"):
        from tofnet.io.event_source import EventSource
        EventSource.__init__(self, path)
        self.h5, self.handle, self.gt = h5, h5.handle, None
        self.detail = f"MVSEC layout, davis/{side}"
        if f"davis/{side}/events" not in h5:
            raise DataError(located(path, None, f"no davis/{side}/events"))
        self.rows = h5.dataset(f"davis/{side}/events")
        if self.rows.ndim != 2 or self.rows.shape[1] != 4:
            raise DataError(located(path, None, f"davis/{side}/events: expected (n, 4) rows x, y, t, p; "
                                                f"got shape {self.rows.shape}"))
        self.n_events = self.n_rows = int(self.rows.shape[0])
        if f"davis/{side}/image_raw" in h5 and h5.dataset(f"davis/{side}/image_raw").ndim == 3:
            images = h5.dataset(f"davis/{side}/image_raw")
            height, width = images.shape[1:]
            self.sensor_size = (int(width), int(height))
            self.not_read(f"davis/{side}/image_raw", f"{images.shape[0]} images")
        if f"davis/{side}/imu" in h5 and f"davis/{side}/imu_ts" in h5:
            self.imu = np.column_stack([h5.value(f"davis/{side}/imu_ts"), h5.value(f"davis/{side}/imu")])
        for key in (k for k in h5.keys("davis") if k != side):
            self.not_read(f"davis/{key}")
        gt_path = _companion(path, "_gt", (".hdf5", ".h5"), "the MVSEC ground truth (HDF5)")
        if gt_path is None:
            self.notes.append("no *_gt.hdf5 next to the file: no poses or depth")
            return
        with self._opened_gt(gt_path) as gt:
            if f"davis/{side}/pose" in gt:
                self.trajectory = trajectory_from_matrices(gt.value(f"davis/{side}/pose_ts"), gt.value(
                    f"davis/{side}/pose"), f"{gt_path}:davis/{side}/pose")
            if side == "left" and "davis/left/depth_image_raw" in gt:
                self.frame_gt = DepthImages(gt.dataset("davis/left/depth_image_raw"),
                                            image_times_us(gt, "davis/left/depth_image_raw_ts", 1e6), gt_path,
                                            gt.allow_external)
                self.has_depth = True
        found = " and ".join(what for what, got in (("poses", self.trajectory is not None), ("depth", self.has_depth))
                             if got)
        left_only = "davis/left/depth_image_raw" in gt and side != "left"
        left_only = " (its depth images are davis/left's)" if left_only else ""
        self.notes.append((f"{found} from {gt_path.name}" if found else f"no davis/{side} poses or depth in "
                           f"{gt_path.name}") + left_only)

    def _times(self, lo: int, hi: int) -> np.ndarray:
        from tofnet.io.arrays import seconds_to_us  # as events_from_columns converts them
        return seconds_to_us(self.rows[lo:hi, 2])

    def _rows(self, first: int, last: int, size_hint: int) -> Iterable[np.ndarray]:
        from tofnet.io.events import events_from_columns

        for start in range(first, last, size_hint):
            rows = self.rows[start:min(start + size_hint, last)]
            where = f"{self.path} ({self.rows.name.lstrip('/')} rows {start}..{start + len(rows) - 1})"
            yield events_from_columns({"x": rows[:, 0], "y": rows[:, 1], "t": rows[:, 2], "p": rows[:, 3]}, where)


class M3edSource(_GroundTruthMixin, ColumnsSource):
    """M3ED ``*_data.h5`` (left Prophesee) with ``*_depth_gt.h5`` (or ``*_pose_gt.h5``) ground truth."""

    def __init__(self, path: Path, h5: H5File, side: str = "left"):
        if f"prophesee/{side}/t" not in h5:
            raise DataError(located(path, None, f"no prophesee/{side}/{{x,y,t,p}}"))
        super().__init__(path, h5, f"prophesee/{side}", t_offset=0)
        self.gt = None
        self.detail = f"M3ED layout, prophesee/{side}"
        self.intrinsics, self.sensor_size = read_calib_group(h5, f"prophesee/{side}/calib", path)
        if f"prophesee/{side}/ms_map_idx" in h5 and h5.dataset(f"prophesee/{side}/ms_map_idx").ndim == 1:
            self.ms_index = h5.dataset(f"prophesee/{side}/ms_map_idx")  # M3ED's ms_to_idx (µs from 0: t_offset 0)
        for key in sorted(set(h5.keys()) - {"prophesee"}):
            self.not_read(key)
        gt_path = _companion(path, "_depth_gt", (".h5", ".hdf5"), "the M3ED depth ground truth (HDF5)") or \
            _companion(path, "_pose_gt", (".h5", ".hdf5"), "the M3ED pose ground truth (HDF5)")
        if gt_path is None:
            self.notes.append("no *_depth_gt.h5 or *_pose_gt.h5 next to the file: no poses or depth")
            return
        with self._opened_gt(gt_path) as gt:
            times_us = image_times_us(gt, "ts", 1.0) if "ts" in gt else None
            if side == "left" and "Cn_T_C0" in gt and times_us is not None:  # the left camera's poses
                # Cn_T_C0 maps the first camera frame into camera n: the camera-to-world pose is its inverse.
                self.trajectory = trajectory_from_matrices(times_us * 1e-6, np.linalg.inv(gt.value("Cn_T_C0")),
                                                           f"{gt_path}:Cn_T_C0")
            if side == "left" and "depth/prophesee/left" in gt and times_us is not None:
                self.frame_gt = DepthImages(gt.dataset("depth/prophesee/left"), times_us, gt_path, gt.allow_external)
                self.has_depth = True
        self.notes.append(f"ground truth from {gt_path.name}")


__all__ = ["MvsecSource", "M3edSource", "DepthImages", "matrix_to_quaternion", "trajectory_from_matrices"]
