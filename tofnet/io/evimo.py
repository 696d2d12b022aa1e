"""EVIMO2 v2 sequence folders (NPZ layout), as the dataset ships them.

``<camera>/<category>/<subcategory>/<sequence>/`` holds, per event camera (``samsung_mono``,
``left_camera``, ``right_camera``):

- ``dataset_events_t.npy`` (seconds, float), ``dataset_events_xy.npy`` (``(n, 2)`` column, row),
  ``dataset_events_p.npy`` (0/1), read as memory maps: time windows read only their rows;
- ``dataset_info.npz``: ``meta``, a pickled dictionary (read by ``tofnet.io.npz_object``, which runs
  nothing from the file): ``meta.meta`` the camera (``fx fy cx cy``, ``dist_model`` with ``k1..k4 p1 p2``,
  ``res_x res_y``), ``full_trajectory`` the camera's Vicon poses (camera to world, 200 Hz; samples where
  Vicon lost the camera are left out and counted), ``frames`` the ground-truth frames' times and ids;
- ``dataset_depth.npz``: depth images ``depth_<id>`` (uint16 mm, 0 unknown), the true depth of each event
  from the frame nearest in time (``tofnet.io.frames.FrameDepth``).

Masks, classical frames and the IMU samples are not read (a note says so). The Samsung sensor's
polarity is the opposite of Prophesee's (the dataset's documentation); events keep the file's.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.event_source import EventSource
from tofnet.io.files import present

#: The files that make a folder an EVIMO2 v2 sequence (``tofnet.io.layouts``).
EVENT_FILES = ("dataset_events_t.npy", "dataset_events_xy.npy", "dataset_events_p.npy")
INFO_FILE = "dataset_info.npz"
#: EVIMO2's event cameras (the folder three levels up).
CAMERAS = ("samsung_mono", "left_camera", "right_camera")
#: An event further than this from every depth frame gets no true depth (s); frames come at 60 Hz.
MAX_DEPTH_GAP_S = 0.05


class Evimo2Source(EventSource):
    """An EVIMO2 v2 sequence folder (module docstring)."""

    format = "evimo2"

    def __init__(self, folder: str | Path):
        super().__init__(folder)
        from tofnet.io.npy import map_npy

        for name in EVENT_FILES + (INFO_FILE,):
            if not present(self.path / name, "a file of the EVIMO2 sequence"):
                raise DataError(located(self.path / name, None, "missing: a file of the EVIMO2 v2 sequence"))
        t, xy, p = (map_npy(self.path / name, "EVIMO2 events") for name in EVENT_FILES)
        self.t, self.p = t.reshape(-1), p.reshape(-1)  # (n,) or (n, 1) as the dataset writes them
        n = len(self.t)
        if t.size != n or xy.shape != (n, 2) or self.p.shape != (n,) or p.size != n:
            raise DataError(located(self.path, None, f"the event arrays do not match: t {t.shape}, xy {xy.shape}, "
                                                     f"p {p.shape}; expected (n,) or (n, 1), (n, 2), (n,) or (n, 1)"))
        self.xy, self.n_events, self._total = xy, n, n  # n_events becomes a window's count (set_window)
        parents = self.path.resolve().parents  # <camera>/<category>/<subcategory>/<sequence>
        camera = parents[2].name if len(parents) > 2 and parents[2].name in CAMERAS else ""
        self.detail = "EVIMO2 v2 sequence" + (f", {camera}" if camera else "")
        meta = _mapping(_read_meta(self.path / INFO_FILE), f"{self.path / INFO_FILE}[meta]")
        where = f"{self.path / INFO_FILE}[meta]"
        self.intrinsics, self.sensor_size = _camera(_mapping(meta.get("meta"), f"{where}.meta"), f"{where}.meta")
        self.trajectory = self._poses(meta.get("full_trajectory"), f"{where}.full_trajectory")
        self._depth_frames(meta.get("frames"), f"{where}.frames")
        for name, what in (("dataset_mask.npz", "object masks"), ("dataset_classical.npz", "classical frames")):
            if (self.path / name).exists():
                self.not_read(name, what)
        if meta.get("imu"):
            topics = len(meta["imu"])
            self.not_read("imu", f"IMU of {topics} topic{'s' if topics != 1 else ''} in {INFO_FILE} (the poses give the rotation)")

    def _times(self, lo: int, hi: int) -> np.ndarray:
        from tofnet.io.arrays import times_us_for_search
        return times_us_for_search(np.asarray(self.t[lo:hi]))

    def _rows(self, first: int, last: int, size_hint: int) -> Iterable[np.ndarray]:
        from tofnet.io.arrays import events_from_columns

        for start in range(first, last, size_hint):
            stop = min(start + size_hint, last)
            xy = np.asarray(self.xy[start:stop])
            yield events_from_columns({"t": np.asarray(self.t[start:stop]), "x": xy[:, 0], "y": xy[:, 1],
                                       "p": np.asarray(self.p[start:stop])}, f"{self.path} (events {start}..{stop - 1})")

    def _packets(self, size_hint: int) -> Iterable[np.ndarray]:
        yield from self._rows(0, self._total, size_hint)

    def _range(self, start: int, stop: int | None) -> tuple[int, int]:
        from tofnet.io.window import first_at_or_after

        lo = first_at_or_after(self._times, self._total, start)
        return lo, self._total if stop is None else max(first_at_or_after(self._times, self._total, stop), lo)

    def _window_packets(self, size_hint: int, start: int, stop: int | None) -> Iterable[np.ndarray]:
        lo, hi = self._range(start, stop)
        self._first_index = lo
        yield from self._rows(lo, hi, size_hint)

    def _window_count(self, start: int, stop: int | None) -> int | None:
        lo, hi = self._range(start, stop)
        return hi - lo

    def first_time(self) -> int | None:
        return int(self._times(0, 1)[0]) if self._total else None

    def _window_end_us(self) -> int | None:
        return self.last_time()

    def last_time(self) -> int | None:
        return int(self._times(self._total - 1, self._total)[0]) if self._total else None

    def _poses(self, samples, where: str):
        from tofnet.io.groundtruth import Trajectory

        if samples is None:
            self.notes.append("no full_trajectory in the metadata: no poses")
            return None
        rows, lost = [], 0
        for k, sample in enumerate(_sequence(samples, where)):
            cam = _mapping(sample, f"{where}[{k}]").get("cam")
            if cam is None:
                lost += 1  # Vicon lost the camera here
                continue
            pos = _mapping(_mapping(cam, f"{where}[{k}].cam").get("pos"), f"{where}[{k}].cam.pos")
            t, q = (_mapping(pos.get(key), f"{where}[{k}].cam.pos.{key}") for key in ("t", "q"))
            rows.append([_number(sample.get("ts", cam.get("ts")), f"{where}[{k}].ts")]
                        + [_number(t.get(a), f"{where}[{k}].cam.pos.t.{a}") for a in "xyz"]
                        + [_number(q.get(a), f"{where}[{k}].cam.pos.q.{a}") for a in "xyzw"])
        if lost:
            self.notes.append(f"{lost:,} of {lost + len(rows):,} pose samples without the camera (Vicon lost it): "
                              "the poses are interpolated across them")
        table = np.asarray(rows, dtype=np.float64).reshape(-1, 8)
        return Trajectory(table[:, 0], table[:, 1:4], table[:, 4:8], where)

    def _depth_frames(self, frames, where: str) -> None:
        from tofnet.io.frames import FrameDepth
        from tofnet.io.npy import load_npz

        depth_file = self.path / "dataset_depth.npz"
        if not present(depth_file, "the EVIMO2 depth frames"):
            self.notes.append("no dataset_depth.npz: no true depth")
            return
        keys, _ = load_npz(depth_file, wanted=())
        by_id = {int(key[6:]): key for key in keys if key.startswith("depth_") and key[6:].isdigit()}
        gt_frames = [(k, frame) for k, frame in enumerate(_sequence(frames if frames is not None else [], where))
                     if "gt_frame" in _mapping(frame, f"{where}[{k}]")]
        ids = [int(_number(frame.get("id"), f"{where}[{k}].id")) for k, frame in gt_frames]
        if any(i not in by_id for i in ids) and len(gt_frames) == len(by_id):
            # not keyed by id: in order, as EVIMO2's own viewer pairs them (sorted keys, frames in order)
            self.notes.append(f"the depth images of {depth_file.name} are not keyed by frame id: taken in order")
            ids = sorted(by_id)
        times, names, missing = [], [], 0
        for (k, frame), frame_id in zip(gt_frames, ids):
            if frame_id not in by_id:
                missing += 1
                continue
            times.append(_number(frame.get("ts"), f"{where}[{k}].ts"))
            names.append(by_id[frame_id])
        if missing:
            self.notes.append(f"{missing:,} ground-truth frames of the metadata have no depth image in "
                              f"{depth_file.name}: not used")
        if not names:
            self.notes.append(f"no depth frame of {depth_file.name} is in the metadata's frames: no true depth")
            return
        order = np.argsort(times, kind="stable")
        times_us = np.round(np.asarray(times)[order] * 1e6).astype(np.int64)
        names = [names[i] for i in order]
        if np.any(np.diff(times_us) <= 0):
            raise DataError(located(where, None, "the depth frames' times must increase"))

        def read_frame(k: int) -> np.ndarray:
            _, arrays = load_npz(depth_file, wanted=(names[k],))
            return arrays[names[k]].astype(np.float64) * 1e-3  # mm -> m; 0 (unknown) becomes NaN in FrameDepth

        first = load_npz(depth_file, wanted=(names[0],))[1][names[0]]
        if first.ndim != 2:
            raise DataError(located(f"{depth_file}[{names[0]}]", None, f"expected a depth image (H, W), got shape "
                                                                      f"{first.shape}"))
        self.frame_gt = FrameDepth(times_us, read_frame, first.shape, depth_file, max_gap_s=MAX_DEPTH_GAP_S,
                                   what="EVIMO2 depth frames")
        self.has_depth = True
        self.notes.append(f"true depth from {len(names):,} depth frames of {depth_file.name}")


def open_evimo2(folder: Path):
    """The ``EventSource`` of an EVIMO2 v2 sequence folder, its ground truth checked against its events."""
    from tofnet.io.frames import check_overlap

    source = Evimo2Source(folder)
    if source.frame_gt is not None:
        check_overlap(source, source.frame_gt, source.frame_gt.source)
    return source


def _read_meta(path: Path):
    from tofnet.io.npz_object import read_npz_object
    return read_npz_object(path, "meta")


def _camera(camera: dict, where: str):
    from tofnet.io.calibration import intrinsics_from

    model = str(camera.get("dist_model", "radtan"))
    names = ("k1", "k2", "k3", "k4") if model in ("equidistant", "fisheye", "kb4") else ("k1", "k2", "p1", "p2", "k3")
    values = [_number(camera.get(key), f"{where}.{key}") for key in ("fx", "fy", "cx", "cy")]
    coefficients = [_number(camera.get(key, 0.0), f"{where}.{key}") for key in names]
    try:
        intrinsics = intrinsics_from(values, coefficients, model)
    except ValueError as err:
        raise DataError(located(where, None, str(err))) from None
    size = tuple(int(_number(camera.get(key), f"{where}.{key}")) for key in ("res_x", "res_y"))
    return intrinsics, size


def _mapping(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise DataError(located(where, None, f"expected a dictionary, got {type(value).__name__}"))
    return value


def _sequence(value, where: str) -> list:
    if not isinstance(value, (list, tuple)):
        raise DataError(located(where, None, f"expected a list, got {type(value).__name__}"))
    return list(value)


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(value)):
        raise DataError(located(where, None, f"expected a finite number, got {str(value)[:40]!r}"))
    return float(value)
