"""Recordings parsed whole (ECD folders, ``events.txt``, numpy files) served as an ``EventSource``.

With a time window, ``events.txt`` and ``.npy`` read only the window's bytes or rows
(``tofnet.io.text_window``, ``tofnet.io.arrays.read_npy_window``); the rest is parsed
whole and cut by a binary search on the sorted times.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.recording import Recording
from tofnet.io.event_source import EventSource, ProgressHook


class RecordingSource(EventSource):
    """A recording already in memory (ECD folders, text and numpy files), served in chunks."""

    def __init__(self, recording: Recording, format: str, path: str | Path, span: tuple[int, int] | None = None):
        super().__init__(path)
        self._span = span  # (first, last) event µs of the file when only a window of it was read
        self.format = format
        self.recording = recording
        self.sensor_size = recording.sensor_size
        self.intrinsics = recording.intrinsics
        self.trajectory = recording.trajectory
        self.imu = recording.imu
        self.n_events = len(recording.events)
        self.frame_gt = recording.frame_gt
        self.has_depth = recording.gt_depth is not None or recording.frame_gt is not None
        self.notes = list(recording.notes)

    def _packets(self, size_hint: int) -> Iterable[np.ndarray]:
        events = self.recording.events
        for start in range(0, len(events), size_hint):
            yield events[start:start + size_hint]

    def _depth(self, events: np.ndarray, first_index: int) -> np.ndarray | None:
        if self.recording.gt_depth is None:  # ground truth as frames (an EVIMO sequence file)
            return super()._depth(events, first_index)
        return self.recording.gt_depth[first_index:first_index + len(events)]

    def first_time(self) -> int | None:
        events = self.recording.events
        return self._span[0] if self._span else int(events["t"][0]) if len(events) else None

    def _window_end_us(self) -> int | None:
        return self._span[1] if self._span else int(self.recording.events["t"][-1])

    def last_time(self) -> int | None:
        return self._window_end_us()  # known without decoding

    def set_window(self, window) -> None:
        # Loaded whole already (text and numpy have no index): the window is a slice, found by
        # binary search on the sorted times (a time going back is caught by the reader first).
        super().set_window(window)
        start, stop = self.window
        t = self.recording.events["t"]
        lo = int(np.searchsorted(t, start, side="left"))
        hi = len(t) if stop is None else max(int(np.searchsorted(t, stop, side="left")), lo)
        if hi == lo:
            raise self.empty_window()
        recording = self.recording
        self.recording = Recording(events=recording.events[lo:hi], intrinsics=recording.intrinsics,
                                   trajectory=recording.trajectory, sensor_size=recording.sensor_size,
                                   gt_depth=None if recording.gt_depth is None else recording.gt_depth[lo:hi],
                                   imu=recording.imu, source=recording.source, notes=recording.notes,
                                   frame_gt=recording.frame_gt)
        self.n_events = hi - lo

    def _window_packets(self, size_hint: int, start: int, stop: int | None) -> Iterable[np.ndarray]:
        return self._packets(size_hint)  # already the window's slice (set_window)

    def read(self, progress: ProgressHook | None = None) -> Recording:
        recording = self.recording
        # Attributes set after opening (a sensor size override) win over what was read.
        recording.sensor_size, recording.intrinsics = self.sensor_size, self.intrinsics
        recording.trajectory, recording.imu = self.trajectory, self.imu
        recording.notes = list(self.notes)  # the file's (rounded times) and any added since
        if recording.gt_depth is None and self.frame_gt is not None:  # per event, as every reader's read() gives
            recording.gt_depth = self.frame_gt.at_events(recording.events)
        if progress is not None:
            progress(len(recording.events), len(recording.events))
        return recording


def read_in_memory(path: Path, kind: str, columns, window=None) -> tuple[Recording, tuple[int, int] | None]:
    """The recording, and for a ``.npy`` read through a time window, the file's (first, last) event µs."""
    from tofnet.io.calibration import NO_CALIBRATION
    from tofnet.io.ecd import attach_dataset_files, attach_sidecars, read_ecd
    from tofnet.io.events import read_events_npy, read_events_txt

    from tofnet.io.ecd import EVENTS, GT_DEPTH

    span = None
    notes: list[str] = []
    if kind == "ecd" and window is not None and (path / EVENTS).is_file() and not _exists(path / GT_DEPTH):
        # Only the window's bytes of events.txt are parsed (true depth per event needs the whole file).
        from tofnet.io.text_window import read_text_window
        events, *span = read_text_window(path / EVENTS, window, notes)
        recording = attach_sidecars(Recording(events=events, source=str(path), notes=notes), path)
        recording = attach_dataset_files(recording, path)
    elif kind == "ecd":
        recording = read_ecd(path)
    else:
        depth_name = f"{path.stem}_depth.npy"
        if kind == "text" and window is not None and not _exists(path.parent / depth_name):
            from tofnet.io.text_window import read_text_window
            events, *span = read_text_window(path, window, notes)
        elif kind == "text":
            events = read_events_txt(path, notes)  # notes: how many times were rounded to the µs
        elif kind == "npy" and window is not None:
            # A memory map: only the window's rows are read (the other formats here are parsed whole).
            from tofnet.io.arrays import read_npy_window
            events, first, lo, hi, last = read_npy_window(path, columns, window)
            span, depth_name = (first, last), None
        else:
            events = read_events_npy(path, columns=columns)
        recording = attach_sidecars(Recording(events=events, source=str(path), notes=notes), path.parent,
                                    gt_depth_name=depth_name, note_missing=kind != "npz")
        if kind == "npy" and span is not None and _exists(path.parent / f"{path.stem}_depth.npy"):
            from tofnet.io.ecd import read_gt_depth
            from tofnet.io.npy import map_npy
            total = len(map_npy(path, "events file"))
            recording.gt_depth = read_gt_depth(path.parent / f"{path.stem}_depth.npy", total)[lo:hi]
        if kind == "npz":
            from tofnet.io.arrays import apply_npz_metadata, npz_unread
            from tofnet.io.evimo import NPZ_READ, NPZ_SIGNATURE, apply_evimo_npz
            from tofnet.io.npy import load_npz
            apply_npz_metadata(recording, path)
            keys, _ = load_npz(path, (), "events file")
            unread = npz_unread(path, keys)
            if set(NPZ_SIGNATURE) <= set(keys):  # an EVIMO / EVIMO2 v1 sequence file
                apply_evimo_npz(recording, path)
                unread = [key for key in unread if key not in NPZ_READ]
            if unread:  # nothing dropped unsaid
                recording.notes.append(f"not read: array{'s' if len(unread) > 1 else ''} {', '.join(unread)} of "
                                       f"{path.name}")
            if recording.intrinsics is None:
                recording.notes.append(NO_CALIBRATION)
    if len(recording.events) == 0 and span is None:
        raise DataError(located(path, None, "no events"))
    return recording, (tuple(span) if span is not None else None)


def _exists(path: Path) -> bool:
    return path.exists() or path.is_symlink()
