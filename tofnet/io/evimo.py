"""EVIMO2 v2 sequence folders (NPZ layout), and EVIMO / EVIMO2 v1 sequence files, as the datasets ship them.

``<camera>/<category>/<subcategory>/<sequence>/`` holds, per event camera (``samsung_mono``,
``left_camera``, ``right_camera``):

- ``dataset_events_t.npy`` (seconds, float), ``dataset_events_xy.npy`` (``(n, 2)`` column, row),
  ``dataset_events_p.npy`` (0/1), read as memory maps: time windows read only their rows;
- ``dataset_info.npz``: ``meta``, a pickled dictionary (read by ``tofnet.io.npz_object``, which runs
  nothing from the file): ``meta.meta`` the camera (``fx fy cx cy``, ``dist_model`` with ``k1..k4 p1 p2``,
  ``res_x res_y``), ``full_trajectory`` the camera's Vicon poses (camera to the recording's first camera
  frame, 200 Hz), ``frames`` the ground-truth frames' times and ids;
- ``dataset_depth.npz``: depth images ``depth_<i>`` for the frame at position ``i`` of ``meta['frames']`` (uint16
  mm, Z, 0 unknown; EVIMO's packaging numbers them so, from 0 in every sub-sequence), the true depth of each event
  from the frame nearest in time (``tofnet.io.frames.FrameDepth``).

Masks, classical frames and the IMU samples are not read (a note says so). The Samsung sensor's
polarity is the opposite of Prophesee's (the dataset's documentation); events keep the file's.

EVIMO and EVIMO2 v1 ship a sequence as one ``.npz``: ``events`` ``(n, 4)`` (t s, x, y, p), ``depth``
``(frames, H, W)`` mm, ``meta`` as above (one frame per depth image, in order), ``K``, ``D``. The events are
read as any ``.npz``'s; ``apply_evimo_npz`` adds the camera, poses and depth frames.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.event_source import EventSource
from tofnet.io.evimo_meta import camera, ground_truth_frames, poses, read_meta
from tofnet.io.files import present
from tofnet.io.layouts import evimo2_camera
from tofnet.io.recording import Recording

#: The files that make a folder an EVIMO2 v2 sequence (``tofnet.io.layouts``).
EVENT_FILES = ("dataset_events_t.npy", "dataset_events_xy.npy", "dataset_events_p.npy")
INFO_FILE = "dataset_info.npz"
#: The arrays of an EVIMO / EVIMO2 v1 sequence file ``apply_evimo_npz`` reads (with ``events``), and those that
#: tell one (``K`` and ``D`` repeat ``meta``'s camera).
NPZ_READ = ("meta", "depth", "K", "D")
NPZ_SIGNATURE = ("events", "meta", "depth", "K")
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
        if n and self.p.dtype.kind in "iu" and int(self.p.max()) > 1:  # one pass over n bytes, so no window hides it
            raise DataError(located(self.path / EVENT_FILES[2], None, f"polarities up to {int(self.p.max())}; expected "
                                    "0/1 (EVIMO2's first NPZ release wrote the time there; it was regenerated in 2022: "
                                    "download the sequence again)"))
        if n and self.t.dtype.kind == "f" and self.t.dtype.itemsize < 8:
            from tofnet.io.arrays import float_time_step
            step = float_time_step(np.asarray(self.t[n - 1:n]))  # sorted: the last is the largest
            if step > 1e-6:
                self.notes.append(f"times are {self.t.dtype} seconds: {step * 1e6:.3g} µs apart at the last event")
        camera_name = evimo2_camera(self.path)
        self.detail = "EVIMO2 v2 sequence" + (f", {camera_name}" if camera_name else "")
        where = f"{self.path / INFO_FILE}[meta]"
        meta = read_meta(self.path / INFO_FILE)
        self.intrinsics, self.sensor_size = camera(meta, where)
        self.trajectory = poses(meta, where, self.notes)
        self._depth_frames(meta, where)
        for name, what in (("dataset_mask.npz", "object masks"), ("dataset_classical.npz", "classical frames")):
            if (self.path / name).exists():
                self.not_read(name, what)
        if camera_name == "samsung_mono":  # EVIMO2's documentation: its polarity is the opposite of Prophesee's
            self.notes.append("samsung_mono: the polarity is the opposite of the Prophesee cameras' (EVIMO2's "
                              "documentation); kept as the file has it")
        if isinstance(meta.get("imu"), dict) and meta["imu"]:
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

    def _depth_frames(self, meta: dict, where: str) -> None:
        from tofnet.io.frames import FrameDepth
        from tofnet.io.npy import load_npz

        depth_file = self.path / "dataset_depth.npz"
        if not present(depth_file, "the EVIMO2 depth frames"):
            self.notes.append("no dataset_depth.npz: no true depth")
            return
        keys, _ = load_npz(depth_file, wanted=())
        by_id = {int(key[6:]): key for key in keys if key.startswith("depth_") and key[6:].isdigit()}
        gt_frames = ground_truth_frames(meta, where)
        # EVIMO's packaging names depth_<i> after the frame's position in meta['frames'] (pydvs evimo-gen.py); by
        # its id where that matches more; in order (EVIMO2's viewer) when there is one image per frame named otherwise
        positions, ids = [k for k, _, _ in gt_frames], [frame_id for _, frame_id, _ in gt_frames]

        def matched(numbers: list[int]) -> int:
            return sum(number in by_id for number in numbers)

        keys = positions if matched(positions) >= matched(ids) else ids
        if matched(keys) < len(gt_frames) and len(gt_frames) == len(by_id):  # one image each, named otherwise
            self.notes.append(f"the depth images of {depth_file.name} are named after neither the frames' positions "
                              "nor their ids: taken in order")
            keys = sorted(by_id)
        times, names, missing = [], [], 0
        for (_, _, ts), frame_id in zip(gt_frames, keys):
            if frame_id not in by_id:
                missing += 1
                continue
            times.append(ts)
            names.append(by_id[frame_id])
        if missing:
            self.notes.append(f"{missing:,} ground-truth frames of the metadata have no depth image in "
                              f"{depth_file.name}: not used")
        if not names:
            self.notes.append(f"no depth frame of {depth_file.name} is in the metadata's frames: no true depth")
            return
        times_us = _increasing_us(times, f"{where}.frames")

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


def open_evimo2(folder: Path) -> Evimo2Source:
    """The ``EventSource`` of an EVIMO2 v2 sequence folder, its ground truth checked against its events."""
    from tofnet.io.frames import check_overlap

    source = Evimo2Source(folder)
    if source.frame_gt is not None:
        check_overlap(source, source.frame_gt, source.frame_gt.source)
    return source


def apply_evimo_npz(recording: Recording, path: Path) -> None:
    """Give ``recording`` (the events of an EVIMO / EVIMO2 v1 ``.npz``) the camera, poses and depth frames of
    its ``meta`` and ``depth`` (module docstring); the file's wins over side files."""
    from tofnet.io.frames import FrameDepth
    from tofnet.io.npy import load_npz, npz_shape

    where = f"{path}[meta]"
    meta = read_meta(path)
    recording.intrinsics, recording.sensor_size = camera(meta, where)
    recording.trajectory = poses(meta, where, recording.notes)
    frames = [(position, ts) for position, _, ts in ground_truth_frames(meta, where)]
    shape, _ = npz_shape(path, "depth", "EVIMO sequence file")
    count = len(meta.get("frames") or [])  # one image per frame of the metadata, in its order (pydvs evimo-gen.py)
    if len(shape) != 3 or shape[0] != count:
        raise DataError(located(f"{path}[depth]", None, f"expected one depth image per frame of the metadata "
                                                        f"({count}, H, W), got shape {shape}"))
    cache: dict[str, np.ndarray] = {}

    def depth() -> np.ndarray:  # the whole array, read once when the ground truth is first asked for
        if "depth" not in cache:
            cache["depth"] = load_npz(path, ("depth",), "EVIMO sequence file")[1]["depth"]
        return cache["depth"]

    if len(frames):
        recording.frame_gt = FrameDepth(_increasing_us([ts for _, ts in frames], f"{where}.frames"),
                                        lambda k: depth()[frames[k][0]].astype(np.float64) * 1e-3, shape[1:], path,
                                        max_gap_s=MAX_DEPTH_GAP_S, what="EVIMO depth frames")
        recording.notes.append(f"true depth from {len(frames):,} depth frames of {path.name}")


def _increasing_us(times_s: list[float], where: str) -> np.ndarray:
    times_us = np.round(np.asarray(times_s, dtype=np.float64) * 1e6).astype(np.int64)
    if np.any(np.diff(times_us) <= 0):
        raise DataError(located(where, None, "the depth frames' times must increase"))
    return times_us
