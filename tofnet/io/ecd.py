"""Recordings in the Event Camera Dataset (ECD) folder layout, as ``slider_depth``.

A folder holds ``events.txt`` (``t x y p``) and optionally ``calib.txt``,
``groundtruth.txt`` and ``imu.txt``; tofnet adds ``sensor_size.txt`` (``width
height``) and ``events_depth.npy`` (true depth per event, metres) for simulated
recordings. ECD's ``images.txt`` and ``images/`` are not used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.events import sensor_size_problem
from tofnet.io.calibration import NO_CALIBRATION, read_calibration, write_calibration
from tofnet.io.files import write_text_atomic
from tofnet.io.npy import load_npy, write_npy
from tofnet.io.events import read_events_txt, write_events_txt
from tofnet.io.groundtruth import read_groundtruth, read_table, write_groundtruth
from tofnet.io.recording import Intrinsics, Recording

EVENTS = "events.txt"
CALIBRATION = "calib.txt"
GROUNDTRUTH = "groundtruth.txt"
IMU = "imu.txt"
SENSOR_SIZE = "sensor_size.txt"
GT_DEPTH = "events_depth.npy"


def read_imu(path: str | Path) -> np.ndarray:
    """ECD ``imu.txt``: ``t ax ay az gx gy gz`` (s, m/s², rad/s) as a float64 ``(n, 7)`` array."""
    values, _ = read_table(path, ("t", "ax", "ay", "az", "gx", "gy", "gz"), "IMU sample")
    return values


def read_sensor_size(path: str | Path) -> tuple[int, int]:
    """``sensor_size.txt``: one line ``width height`` in pixels, within the documented
    maximum (``tofnet.events.MAX_SENSOR_SIDE``, ``MAX_SENSOR_PIXELS``)."""
    values, lines = read_table(path, ("width", "height"), "sensor size")
    if len(values) != 1:
        raise DataError(located(path, None, f"expected one line 'width height', found {len(values)}"))
    width, height = values[0]
    if width != int(width) or height != int(height) or width < 1 or height < 1:
        raise DataError(located(path, int(lines[0]), f"expected positive whole numbers 'width height' in pixels, "
                                                     f"got {width:g} {height:g}"))
    problem = sensor_size_problem(int(width), int(height))
    if problem:
        raise DataError(located(path, int(lines[0]), f"sensor size: {problem}"))
    return int(width), int(height)


def read_gt_depth(path: str | Path, n_events: int) -> np.ndarray:
    """True depth per event (float64 metres, NaN where unknown), checked against the event count.

    Every known depth must be finite and positive: infinities and depths <= 0 are refused.
    """
    path = Path(path)
    depth = load_npy(path, "depth file")
    if depth.dtype.kind not in "iuf" or depth.shape != (n_events,):
        raise DataError(located(path, None, f"expected {n_events} depths (one per event, float metres), "
                                            f"got an array of shape {depth.shape} and dtype {depth.dtype}"))
    depth = depth.astype(np.float64)
    bad = np.flatnonzero(~np.isnan(depth) & ~((depth > 0) & np.isfinite(depth)))
    if bad.size:
        raise DataError(located(path, None, f"event {int(bad[0])}: true depth {depth[bad[0]]:g} m; expected a "
                                            "finite depth > 0 (or NaN where unknown)"))
    return depth


def attach_sidecars(recording: Recording, folder: Path, gt_depth_name: str | None = GT_DEPTH,
                    note_missing: bool = True) -> Recording:
    """Add the calibration, poses, IMU, sensor size and true depth found in ``folder``.

    A side file that exists but is not a regular file (a folder, a FIFO, ...) is an
    error, not silently skipped. ``note_missing``: note a missing ``calib.txt`` (not when the
    caller may still find the intrinsics in the file itself).
    """
    if _present(folder / CALIBRATION):
        recording.intrinsics = read_calibration(folder / CALIBRATION)
    elif note_missing:
        recording.notes.append(NO_CALIBRATION)
    if _present(folder / GROUNDTRUTH):
        recording.trajectory = read_groundtruth(folder / GROUNDTRUTH)
    if _present(folder / IMU):
        recording.imu = read_imu(folder / IMU)
    if _present(folder / SENSOR_SIZE):
        recording.sensor_size = read_sensor_size(folder / SENSOR_SIZE)
    if gt_depth_name is not None and _present(folder / gt_depth_name):
        recording.gt_depth = read_gt_depth(folder / gt_depth_name, len(recording.events))
    return recording


def _present(path: Path) -> bool:
    return path.exists() or path.is_symlink()


#: Files that datasets ship beside events.txt and tofnet does not read, and what they hold.
NOT_READ = {"images.txt": "the list of the APS frames (images/)"}
#: Beside EVIMO's ``meta.txt``: its depth and mask frames.
EVIMO_NOT_READ = {"img": "EVIMO's depth and mask frames (16-bit colour PNGs; EVIMO's NPZ release holds them as "
                         "arrays)"}
#: EVIMO's TXT layout: its metadata beside events.txt (camera, Vicon poses, frames).
EVIMO_META = "meta.txt"


def attach_dataset_files(recording: Recording, folder: Path) -> Recording:
    """Take the camera and poses of EVIMO's ``meta.txt`` in an ECD-like ``folder`` when there is one (they win over
    ``calib.txt``), and name the dataset files tofnet does not read (nothing a dataset ships is passed over unsaid)."""
    if _present(folder / EVIMO_META):
        from tofnet.io.evimo_meta import camera, poses, read_meta_text

        meta, where = read_meta_text(folder / EVIMO_META), str(folder / EVIMO_META)
        recording.intrinsics, size = camera(meta, where)
        recording.sensor_size = recording.sensor_size or size
        recording.trajectory = poses(meta, where, recording.notes) or recording.trajectory
        recording.notes = [note for note in recording.notes if note != NO_CALIBRATION]
        recording.notes.append(f"camera and poses from {EVIMO_META} (EVIMO's TXT layout)")
    unread = {**NOT_READ, **(EVIMO_NOT_READ if _present(folder / EVIMO_META) else {})}
    recording.notes.extend(f"not read: {name}, {what}" for name, what in unread.items() if _present(folder / name))
    return recording


def read_ecd(folder: str | Path) -> Recording:
    """Read an ECD recording folder (``events.txt`` required, the rest optional)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(located(folder, None, "not a folder; an ECD recording is a folder holding events.txt"))
    if not _present(folder / EVENTS):
        from tofnet.errors import quote
        from tofnet.io.detect import event_files_in
        found = event_files_in(folder)
        held = "" if not found else (f"; it holds event files ({', '.join(quote(n, 40) for n in found[:4])}"
                                     f"{f' and {len(found) - 4} more' if len(found) > 4 else ''}): give one of them "
                                     "(tofnet batch runs many)")
        raise DataError(located(folder, None, f"no {EVENTS}; an ECD recording folder needs {EVENTS} "
                                              f"(lines 't x y p': seconds, column, row, polarity){held}"))
    notes: list[str] = []
    events = read_events_txt(folder / EVENTS, notes)
    recording = Recording(events=events, source=str(folder), notes=notes)
    return attach_dataset_files(attach_sidecars(recording, folder), folder)


def write_ecd(folder: str | Path, events: np.ndarray, *, intrinsics: Intrinsics | None,
              times=None, positions=None, quaternions=None,
              sensor_size: tuple[int, int] | None = None, gt_depth: np.ndarray | None = None) -> None:
    """Write an ECD recording folder (created if needed).

    ``events.txt`` always; ``calib.txt`` when ``intrinsics`` is given;
    ``groundtruth.txt`` when poses are given (``times`` s, ``positions`` m,
    ``quaternions`` ``qx qy qz qw`` camera-to-world); ``sensor_size.txt`` (width,
    height px) and ``events_depth.npy`` (metres per event) when given. Each file is
    written atomically.
    """
    folder = Path(folder)
    poses = (times, positions, quaternions)
    if any(p is not None for p in poses) and any(p is None for p in poses):
        raise DataError(located(folder, None, "poses need all of times, positions and quaternions"))
    if gt_depth is not None and np.shape(gt_depth) != (len(events),):
        raise DataError(located(folder / GT_DEPTH, None, f"expected {len(events)} depths (one per event), "
                                                         f"got shape {np.shape(gt_depth)}"))
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise DataError(located(folder, None, f"cannot create the folder: {err.strerror or err}")) from None
    write_events_txt(folder / EVENTS, events)
    if intrinsics is not None:
        write_calibration(folder / CALIBRATION, intrinsics)
    if times is not None:
        write_groundtruth(folder / GROUNDTRUTH, times, positions, quaternions)
    if sensor_size is not None:
        width, height = (int(v) for v in sensor_size)
        write_text_atomic(folder / SENSOR_SIZE, f"{width} {height}\n")
    if gt_depth is not None:
        write_npy(folder / GT_DEPTH, np.asarray(gt_depth, dtype=np.float64))


#: Every file name ``read_ecd`` may read in a recording folder.
SIDE_FILES = (EVENTS, CALIBRATION, GROUNDTRUTH, IMU, SENSOR_SIZE, GT_DEPTH)


def recording_files(path: str | Path) -> list[Path]:
    """The files a recording at ``path`` is read from (a folder's, or a file and its
    side files); outputs must not overwrite any of them."""
    path = Path(path)
    try:
        if path.is_dir():
            return [path / name for name in SIDE_FILES if _present(path / name)]
        names = [name for name in SIDE_FILES if name not in (EVENTS, GT_DEPTH)] + [f"{path.stem}_depth.npy"]
        return [path] + [path.parent / name for name in names if _present(path.parent / name)]
    except (OSError, ValueError):  # a name the system refuses (too long, NUL): the reader says so in one line
        return [path]
