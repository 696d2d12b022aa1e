"""Recordings in, depth out: event files, ECD folders, ground truth, calibration, depth files.

``read_recording`` is the one entry point the CLI and examples use; the format
modules underneath are ``ecd``, ``events``, ``groundtruth``, ``calibration`` and
``depth``. See ``docs/formats.md``.
"""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import DataError, located
from tofnet.io.calibration import read_calibration, write_calibration
from tofnet.io.depth import read_depth, write_depth
from tofnet.io.ecd import attach_sidecars, read_ecd, read_imu, write_ecd
from tofnet.io.events import (events_from_columns, read_events_npy, read_events_txt, write_events_npy,
                              write_events_txt)
from tofnet.io.groundtruth import (Trajectory, VelocitySamples, read_groundtruth, read_velocity_samples,
                                   write_groundtruth, write_velocity_samples)
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording, VelocitySource

#: File suffixes ``read_recording`` accepts besides a folder.
EVENT_SUFFIXES = (".txt", ".npy", ".npz")


def read_recording(path: str | Path, sensor_size: tuple[int, int] | None = None) -> Recording:
    """Read a recording from an ECD folder, an events ``.txt`` or a ``.npy``/``.npz`` events file.

    For a file, ``calib.txt``, ``groundtruth.txt``, ``imu.txt`` and ``sensor_size.txt``
    in the same folder are read too, and ``<stem>_depth.npy`` as the true depth per
    event. ``sensor_size`` (width, height px), when given, overrides ``sensor_size.txt``.
    Raises ``DataError`` for a missing path, an unknown format or no events.
    """
    path = Path(path)
    if not path.exists():
        raise DataError(located(path, None, "no such file or folder; expected an ECD folder or an events "
                                            "file (.txt, .npy, .npz)"))
    if path.is_dir():
        recording = read_ecd(path)
    elif path.suffix in EVENT_SUFFIXES:
        events = read_events_txt(path) if path.suffix == ".txt" else read_events_npy(path)
        recording = attach_sidecars(Recording(events=events, source=str(path)), path.parent,
                                    gt_depth_name=f"{path.stem}_depth.npy")
    else:
        raise DataError(located(path, None, f"unknown recording format {path.suffix!r}; expected an ECD folder "
                                            "or an events file (.txt, .npy, .npz)"))
    if len(recording.events) == 0:
        raise DataError(located(path, None, "no events"))
    if sensor_size is not None:
        width, height = (int(v) for v in sensor_size)
        if width < 1 or height < 1:
            raise DataError(f"sensor size must be positive, got {width}x{height}")
        recording.sensor_size = (width, height)
    return recording


__all__ = [
    "read_recording", "read_ecd", "write_ecd", "read_imu", "attach_sidecars",
    "read_events_txt", "write_events_txt", "read_events_npy", "write_events_npy", "events_from_columns",
    "read_calibration", "write_calibration",
    "Trajectory", "VelocitySamples", "read_groundtruth", "write_groundtruth", "read_velocity_samples",
    "write_velocity_samples",
    "read_depth", "write_depth",
    "Recording", "Intrinsics", "VelocitySource", "ConstantVelocity",
]
