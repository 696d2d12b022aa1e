"""MVSEC, TUM-VIE and M3ED sequence folders (see ``tofnet.io.sequences``), as the datasets ship them.

- **MVSEC** ``<seq>/<seq>_data.hdf5`` + ``<seq>_gt.hdf5`` (poses ``davis/left/pose``, depth images
  ``davis/left/depth_image_raw`` at ``depth_image_raw_ts``, raw pixels) and the Kalibr calibration
  ``<scene>_calib/camchain-imucam-<scene>.yaml`` (``cam0`` left, ``cam1`` right; in the folder or
  the one above it, where the dataset's ``<scene>_calib.zip`` unpacks beside its sequences).
- **TUM-VIE** ``<seq>/<seq>-events_{left,right}.h5`` (``events/{x,y,t,p}``, µs), the calibration
  JSON ``camera-calibration{A,B}.json`` (cameras 2 and 3 are the left and right event cameras;
  in the folder or the one above it) and, from ``<seq>-vi_gt_data/``, ``mocap_data.txt``
  (``t[µs] tx ty tz qx qy qz qw`` of the mocap marker; camera poses through ``T_imu_cam`` of the
  calibration and ``T_imu_marker`` of ``mocap-imu-calibration{A,B}.json``) and ``imu_data.txt``
  (``t[µs]`` then gyro and accelerometer, in the order its header names, EuRoC's by default).
  TUM-VIE has no depth ground truth.
- **M3ED** ``<seq>/<seq>_data.h5`` (``prophesee/{left,right}``, calibration inside) + ``<seq>_depth_gt.h5``
  (depth images ``depth/prophesee/left`` at ``ts``, poses ``Cn_T_C0``) or ``<seq>_pose_gt.h5``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.files import present
from tofnet.io.layouts import PATTERNS, matches


def _one(folder: Path, pattern: str, what: str) -> Path:
    found = matches(folder, pattern)
    if not found:
        raise DataError(located(folder / pattern, None, f"missing: {what}"))
    if len(found) > 1:
        raise DataError(located(folder, None, f"{len(found)} files {pattern} ({found[0].name}, {found[1].name}, ...): "
                                              "a sequence folder holds one sequence; give the file instead"))
    return found[0]


def open_other(folder: Path, kind: str, side: str, allow_external: bool):
    """The ``EventSource`` of an MVSEC, TUM-VIE or M3ED sequence folder (module docstring)."""
    from tofnet.io.hdf5_open import open_hdf5
    from tofnet.io.frames import check_overlap

    if kind == "tumvie":
        events = _one(folder, f"*-events_{side}.h5", f"the {side} events of the TUM-VIE sequence")
    else:
        events = _one(folder, PATTERNS[kind], f"the events of the {kind.upper()} sequence")
    source = open_hdf5(events, allow_external, side)
    try:
        if kind == "mvsec":
            _mvsec(folder, source, side)
        elif kind == "tumvie":
            _tumvie(folder, source, events, side)
        elif source.intrinsics is None:
            raise DataError(located(events, None, f"missing: prophesee/{side}/calib (the M3ED camera calibration)"))
        else:
            source.detail = f"M3ED sequence, {side} events"
        if source.frame_gt is not None:
            check_overlap(source, source.frame_gt, source.frame_gt.source)
        elif source.trajectory is not None and hasattr(source.trajectory, "times"):
            check_overlap(source, _Span(source.trajectory.times), source.trajectory.source)
    except BaseException:
        source.close()
        raise
    return source


def complete_file(source, side: str) -> None:
    """An MVSEC or TUM-VIE events file read alone (not its folder) and without intrinsics: the calibration
    the dataset ships, found as for the folder (here or one folder up); nothing when there is none."""
    from tofnet.io.hdf5_datasets import MvsecSource

    path = source.path
    tumvie = path.name.endswith(("-events_left.h5", "-events_right.h5"))
    if source.intrinsics is not None or not (tumvie or isinstance(source, MvsecSource)):
        return
    try:
        if tumvie:
            _tumvie(path.parent, source, path, "left" if path.name.endswith("-events_left.h5") else "right")
        else:
            _mvsec(path.parent, source, side)
    except DataError as err:
        if ": missing: the " not in str(err):
            raise


class _Span:
    """A time span (seconds) with ``FrameDepth.span_us``, for ``check_overlap`` of poses."""

    def __init__(self, times_s):
        self.times_us = np.round(np.asarray(times_s, dtype=np.float64) * 1e6).astype(np.int64)

    def span_us(self) -> tuple[int, int]:
        return int(self.times_us[0]), int(self.times_us[-1])


class _NoneOrSeveral(DataError):
    """No file, or several, where ``_near`` looked (not: one that is not a regular file)."""


def _near(folder: Path, patterns: tuple[str, ...], what: str, prefer: str = "") -> Path:
    """A calibration file in ``folder`` or the one above it; one-line errors when none or several
    (``_NoneOrSeveral``) and when one matching is not a regular file (``tofnet.io.files.present``)."""
    for place in (folder, folder.parent):
        found = sorted({p for pattern in patterns for p in place.glob(pattern) if present(p, f"the {what} file")})
        if prefer and len(found) > 1:
            found = [p for p in found if prefer in p.name] or found
        if len(found) == 1:
            return found[0]
        if found:
            names = ", ".join(p.name for p in found[:3])
            raise _NoneOrSeveral(located(place, None, f"{len(found)} {what} files ({names}): "
                                                      "put the sequence's own in its folder"))
    raise _NoneOrSeveral(located(folder / patterns[0].replace("*", "").lstrip("/"), None,
                                 f"missing: the {what} (looked for {' or '.join(patterns)} in {folder.name}/ and its "
                                 "parent)"))


def _mvsec(folder: Path, source, side: str) -> None:
    from tofnet.io.calibration import read_camera_file
    from tofnet.io.layouts import sequence_name

    scene = (sequence_name(source.path) or "").rstrip("0123456789")
    calib = _near(folder, ("*_calib/camchain-imucam-*.yaml", "camchain-imucam-*.yaml"), "MVSEC calibration", scene)
    camera = "cam0" if side == "left" else "cam1"
    source.intrinsics, size, _ = read_camera_file(calib, camera)
    source.sensor_size = source.sensor_size or size
    source.detail = f"MVSEC sequence, {side} events"
    source.notes.append(f"intrinsics of {camera} from {calib}")


def _tumvie(folder: Path, source, events: Path, side: str) -> None:
    from tofnet.io.calibration import read_camera_file

    calib = _near(folder, ("camera-calibration*.json",), "TUM-VIE camera calibration")
    index = 2 if side == "left" else 3  # cameras 0, 1 are the frame cameras
    source.intrinsics, size, _ = read_camera_file(calib, str(index))
    source.sensor_size = source.sensor_size or size
    source.detail = f"TUM-VIE sequence, {side} events"
    source.notes.append(f"intrinsics of camera {index} from {calib}")
    stem = events.name[:-len(f"-events_{side}.h5")]
    places = [folder / f"{stem}-vi_gt_data", folder]
    if not present(places[0], "the folder of the TUM-VIE ground truth", folder=True):
        places.pop(0)
    gt = next((p for p in places if present(p / "mocap_data.txt", "the TUM-VIE mocap poses (text)")), None)
    if gt is None:
        source.notes.append(f"no {stem}-vi_gt_data/mocap_data.txt: no poses")
        return
    if present(gt / "imu_data.txt", "the TUM-VIE IMU samples (text)"):
        source.imu = read_tumvie_imu(gt / "imu_data.txt")
        source.notes.append(f"IMU from {gt / 'imu_data.txt'}")
    try:
        marker = _near(folder, ("mocap-imu-calibration*.json",), "TUM-VIE mocap-IMU calibration")
    except _NoneOrSeveral as err:
        source.notes.append(f"mocap_data.txt not used (poses of the marker, not the camera): {err}")
        return
    t_imu_cam = _pose_matrix(_json(calib), calib, "value0", "T_imu_cam", index)
    t_imu_marker = _pose_matrix(_json(marker), marker, "value0", "T_imu_marker")
    source.trajectory = read_mocap(gt / "mocap_data.txt", np.linalg.inv(t_imu_marker) @ t_imu_cam)
    source.notes.append(f"poses from {gt / 'mocap_data.txt'} (camera through {calib.name} and {marker.name})")


def _json(path: Path) -> dict:
    from tofnet.io.files import read_text
    from tofnet.io.jsontext import parse_json

    return parse_json(read_text(path, "calibration file", limit=1 << 20), path)


def _pose_matrix(data: object, path: Path, *keys: str | int) -> np.ndarray:
    """A 4x4 transform from Basalt's ``{px, py, pz, qx, qy, qz, qw}`` at ``data[keys[0]][keys[1]]...`` of the
    JSON file ``path``; else a one-line ``DataError`` naming the file and the keys."""
    from tofnet.io.groundtruth import quaternion_to_matrix

    where = ".".join(str(key) for key in keys)
    try:
        entry = data
        for key in keys:
            entry = entry[key]
        values = np.array([float(entry[k]) for k in ("px", "py", "pz", "qx", "qy", "qz", "qw")])
    except (KeyError, IndexError, TypeError, ValueError, OverflowError):
        raise DataError(located(path, None, f"{where}: expected a pose {{px, py, pz, qx, qy, qz, qw}}")) from None
    if not np.isfinite(values).all():
        raise DataError(located(path, None, f"{where}: expected finite numbers, got {values.tolist()}"))
    norm = np.linalg.norm(values[3:])
    if not norm > 0:  # it divides the quaternion below (a NaN pose, blamed on mocap_data.txt)
        raise DataError(located(path, None, f"{where}: the quaternion (qx, qy, qz, qw) is zero: no rotation"))
    matrix = np.eye(4)
    matrix[:3, :3] = quaternion_to_matrix((values[3:] / norm)[None])[0]
    matrix[:3, 3] = values[:3]
    return matrix


def _rows(path: Path, columns: int) -> tuple[list[str], np.ndarray]:
    """The header words and the numbers of a whitespace table with a ``#`` header line."""
    from tofnet.io.calibration import is_number
    from tofnet.io.groundtruth import finite_number, read_text

    header, rows = [], []
    for number, line in enumerate(read_text(path).splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        if fields[0].startswith("#") or not rows and not is_number(fields[0]):
            header = header or [f.lstrip("#") for f in fields if f.lstrip("#")]
            continue
        if len(fields) != columns:
            raise DataError(located(path, number, f"expected {columns} columns, found {len(fields)}"))
        rows.append([finite_number(path, number, f"column {i + 1}", f) for i, f in enumerate(fields)])
    if not rows:
        raise DataError(located(path, None, "no rows"))
    return header, np.asarray(rows)


def read_mocap(path: Path, marker_to_camera: np.ndarray):
    """TUM-VIE ``mocap_data.txt`` (``t[µs] tx ty tz qx qy qz qw``, the marker in the mocap world) as the
    camera's ``Trajectory`` (``marker_to_camera``: the camera pose in the marker frame)."""
    from tofnet.io.groundtruth import quaternion_to_matrix
    from tofnet.io.hdf5_datasets import trajectory_from_matrices

    _, rows = _rows(path, 8)
    marker = np.tile(np.eye(4), (len(rows), 1, 1))
    marker[:, :3, :3] = quaternion_to_matrix(rows[:, 4:8] / np.linalg.norm(rows[:, 4:8], axis=1, keepdims=True))
    marker[:, :3, 3] = rows[:, 1:4]
    return trajectory_from_matrices(rows[:, 0] * 1e-6, marker @ marker_to_camera, path)


def read_tumvie_imu(path: Path) -> np.ndarray:
    """TUM-VIE ``imu_data.txt`` as tofnet's IMU rows ``(n, 7)``: t s, accel m/s², gyro rad/s."""
    header, rows = _rows(path, 7)
    names = [h.lower() for h in header[1:7]]
    accel_first = len(names) == 6 and names[0].startswith("a")
    accel, gyro = (rows[:, 1:4], rows[:, 4:7]) if accel_first else (rows[:, 4:7], rows[:, 1:4])
    return np.column_stack([rows[:, 0] * 1e-6, accel, gyro])
