"""Dataset sequence folders as recordings: DSEC, MVSEC, TUM-VIE, M3ED and EVIMO2, as the datasets ship them.

A folder is recognised by its layout (``sequence_kind``) and opened as one recording with
what the dataset ships beside the events (``open_sequence``):

- **DSEC** ``<seq>/events/{left,right}/events.h5`` (+ ``rectify_map.h5``),
  ``<seq>/calibration/cam_to_cam.yaml`` and, for the left camera, the disparity ground truth
  ``<seq>/disparity/event/*.png`` (disparity x 256, 16 bit, 0 unknown) with
  ``<seq>/disparity/timestamps.txt`` (µs, one per image). Disparity is turned into depth with
  the reprojection matrix ``disparity_to_depth.cams_03`` (depth = f * b / disparity, f the
  rectified focal length, b the stereo baseline). ``rectify=True`` moves the events through the
  rectification map (to the nearest pixel; the camera becomes ``camRect0``/``camRect3``, without
  distortion); without it the ground truth is looked up through the map instead.
- **MVSEC**, **TUM-VIE**, **M3ED**: ``tofnet.io.sequences_other``; **EVIMO2** v2: ``tofnet.io.evimo``.

The layouts are told apart by ``tofnet.io.layouts``. The recording's name (batch plans) is the
sequence folder's (``tofnet.io.layouts.sequence_name``), also for a
path to the events file inside it. A folder that is almost a sequence (calibration or ground
truth missing, ground truth of another time range) is a one-line ``DataError`` naming the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.events import EVENT_DTYPE
from tofnet.io.files import present
from tofnet.io.frames import check_overlap
from tofnet.io.layouts import SIDES

def open_sequence(folder: Path, kind: str, *, side: str | None = None, rectify: bool = False,
                  allow_external: bool = False):
    """The ``EventSource`` of a sequence folder of layout ``kind`` (``sequence_kind``)."""
    if side is not None and side not in SIDES:
        raise DataError(f"--side: expected left or right, got {side!r}")
    if kind == "dsec":
        return open_dsec(folder, side or "left", rectify, allow_external)
    if rectify:
        raise DataError(located(folder, None, "--rectify applies to DSEC sequences (rectify_map.h5); "
                                              f"this is a {kind.upper()} folder"))
    if kind == "evimo2":
        if side is not None:
            raise DataError(located(folder, None, "--side: an EVIMO2 sequence folder holds one camera's events "
                                                  "(its camera is the folder: samsung_mono, left_camera, right_camera)"))
        from tofnet.io.evimo import open_evimo2
        return open_evimo2(folder)
    from tofnet.io.sequences_other import open_other
    return open_other(folder, kind, side or "left", allow_external)


def _required(path: Path, what: str) -> Path:
    if not present(path, what):
        raise DataError(located(path, None, f"missing: {what}"))
    return path


def open_dsec(folder: Path, side: str, rectify: bool, allow_external: bool):
    """A DSEC sequence (module docstring)."""
    from tofnet.io.calibration import read_camera_file
    from tofnet.io.hdf5_open import open_hdf5

    events = _required(folder / "events" / side / "events.h5", f"the {side} events of the DSEC sequence")
    calib = _required(folder / "calibration" / "cam_to_cam.yaml",
                      "the DSEC sequence's calibration (from the dataset's *_calibration.zip)")
    camera, rect_camera = ("cam0", "camRect0") if side == "left" else ("cam3", "camRect3")
    source = open_hdf5(events, allow_external)
    try:
        source.detail = f"DSEC sequence, {side} events" + (", rectified" if rectify else "")
        source.intrinsics, size, _ = read_camera_file(calib, camera)
        source.sensor_size = source.sensor_size or size
        source.notes = [n for n in source.notes if not n.startswith("intrinsics from")]  # DsecSource's own
        source.notes.append(f"intrinsics of {camera} from {calib}")
        map_path = folder / "events" / side / "rectify_map.h5"
        pixel_map = _rectify_map(map_path, source.sensor_size, allow_external) \
            if present(map_path, "the rectification map (HDF5)") else None
        if rectify:
            if pixel_map is None:
                raise DataError(located(map_path, None, "missing: --rectify needs the rectification map"))
            source.remap = PixelRemap(pixel_map, source.sensor_size, str(map_path))
            source.intrinsics, size, _ = read_camera_file(calib, rect_camera)
            source.notes.append(f"events rectified through {map_path.name}; intrinsics of {rect_camera}")
        disparity = folder / "disparity"
        has_disparity = present(disparity, "the folder of the disparity ground truth", folder=True)
        if side == "right":
            if has_disparity:
                source.notes.append("DSEC disparity ground truth is for the left camera: none for the right")
            return source
        if has_disparity:
            q = _q_matrix(calib)
            if not rectify and pixel_map is None:
                raise DataError(located(map_path, None, "missing: the disparity ground truth is rectified, the "
                                                        "rectification map places the events in it"))
            source.frame_gt = dsec_disparity(disparity, q, None if rectify else pixel_map, source.sensor_size)
            check_overlap(source, source.frame_gt, disparity / "timestamps.txt")
            source.has_depth = True
            source.notes.append(f"ground truth: {len(source.frame_gt)} disparity maps from {disparity}")
        else:
            source.notes.append("no disparity/ folder: no ground truth (the DSEC test sequences have none)")
    except BaseException:
        source.close()
        raise
    return source


def _rectify_map(path: Path, sensor_size, allow_external: bool) -> np.ndarray:
    """DSEC ``rectify_map.h5``: ``rectify_map`` ``(H, W, 2)``, the rectified (x, y) of each raw pixel."""
    import h5py

    from tofnet.io.guard import note_read
    from tofnet.io.hdf5_checks import H5File

    note_read(path)
    try:
        handle = h5py.File(path, "r")
    except OSError as err:
        raise DataError(located(path, None, f"not a readable HDF5 file ({err})")) from None
    with handle:
        h5 = H5File(handle, path, allow_external)
        if "rectify_map" not in h5:
            raise DataError(located(path, None, "no dataset rectify_map (H x W x 2)"))
        value = np.asarray(h5.value("rectify_map"), dtype=np.float64)
    if value.ndim != 3 or value.shape[2] != 2 or \
            (sensor_size is not None and value.shape[:2] != (sensor_size[1], sensor_size[0])):
        expected = "H x W x 2" if sensor_size is None else f"{sensor_size[1]} x {sensor_size[0]} x 2"
        raise DataError(located(path, None, f"rectify_map: expected {expected}, got shape {value.shape}"))
    return value


def _q_matrix(calib: Path) -> np.ndarray:
    from tofnet.io.safe_yaml import read_yaml_file

    data = read_yaml_file(calib, "calibration")
    try:
        q = np.asarray(data["disparity_to_depth"]["cams_03"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        q = None
    if q is None or q.shape != (4, 4) or not np.all(np.isfinite(q)) or q[3, 2] == 0:
        raise DataError(located(calib, None, "disparity_to_depth.cams_03: expected the 4x4 reprojection matrix "
                                             "(needed to turn disparity into depth)"))
    return q


def dsec_disparity(folder: Path, q: np.ndarray, pixel_map: np.ndarray | None, sensor_size=None):
    """``FrameDepth`` of DSEC's ``disparity/event/*.png`` at ``disparity/timestamps.txt``.

    Every map must be ``sensor_size`` (``(width, height)``; DSEC's maps are the event camera's
    640x480), or the first map's size when that is not known, within the sensor limits: a map of
    another size is refused from its header, before it is decoded."""
    from tofnet.io.frames import FrameDepth, disparity_to_depth, png_size, read_png16

    stamps = _required(folder / "timestamps.txt", "the times of the disparity maps (µs, one per line)")
    has_maps = present(folder / "event", "the folder of the disparity maps (*.png)", folder=True)
    images = sorted((folder / "event").glob("*.png")) if has_maps else []
    if not images:
        raise DataError(located(folder / "event", None, "missing: the disparity maps (*.png)"))
    times = read_times(stamps)
    if len(times) != len(images):
        raise DataError(located(stamps, None, f"{len(times)} timestamps for {len(images)} disparity maps in "
                                              f"{folder / 'event'}"))
    what, whose = "disparity map", "the events' sensor size" if sensor_size is not None else "the first map's size"
    size = png_size(images[0], what, None if sensor_size is None else tuple(sensor_size), whose)  # header only
    return FrameDepth(times, lambda k: disparity_to_depth(read_png16(images[k], size, what, whose) / 256.0, q),
                      (size[1], size[0]), stamps, pixel_map=pixel_map, what="disparity maps")


def read_times(path: Path, scale: float = 1.0, column: int = 0) -> np.ndarray:
    """Whole µs from column ``column`` of a text file (``#`` comments allowed; ``scale`` µs per unit),
    strictly increasing; one-line errors naming the line."""
    from tofnet.io.groundtruth import finite_number, read_text

    times = []
    for number, line in enumerate(read_text(path).splitlines(), start=1):
        fields = line.replace(",", " ").split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) <= column:
            raise DataError(located(path, number, f"expected at least {column + 1} columns, found {len(fields)}"))
        value = round(finite_number(path, number, "timestamp", fields[column]) * scale)
        if times and value <= times[-1]:
            raise DataError(located(path, number, f"timestamps must increase, got {value} µs after {times[-1]} µs"))
        times.append(value)
    if not times:
        raise DataError(located(path, None, "no timestamps"))
    return np.asarray(times, dtype=np.int64)


class PixelRemap:
    """Events moved to the nearest pixel of ``pixel_map`` (``(H, W, 2)``); those landing outside the
    sensor are counted (``note``), not kept."""

    def __init__(self, pixel_map: np.ndarray, sensor_size, what: str):
        self.map, self.what = pixel_map, what
        self.width, self.height = sensor_size if sensor_size is not None else pixel_map.shape[1::-1]
        with np.errstate(invalid="ignore"):
            self.rounded = np.round(pixel_map)
        self.dropped = 0

    def __call__(self, packet: np.ndarray) -> np.ndarray:
        names = packet.dtype.names
        x, y = packet[names[1]].astype(np.int64), packet[names[2]].astype(np.int64)
        inside = (x < self.map.shape[1]) & (y < self.map.shape[0])
        target = self.rounded[np.where(inside, y, 0), np.where(inside, x, 0)]
        with np.errstate(invalid="ignore"):
            inside &= np.isfinite(target).all(axis=1) & (target[:, 0] >= 0) & (target[:, 0] < self.width) & \
                (target[:, 1] >= 0) & (target[:, 1] < self.height)
        out = np.empty(int(np.count_nonzero(inside)), dtype=EVENT_DTYPE)
        out["t"], out["p"] = packet[names[0]][inside], packet[names[3]][inside]
        out["x"], out["y"] = target[inside, 0], target[inside, 1]
        self.dropped += len(packet) - len(out)
        return out

    def note(self) -> str:
        return f"rectification ({self.what}): {self.dropped:,} events fell outside the rectified image and were left out"
