"""Recordings in, depth out: event files, ECD folders, ground truth, calibration, depth files.

``read_recording`` is the one entry point the CLI and examples use; the format
modules underneath are ``ecd``, ``events``, ``groundtruth``, ``calibration`` and
``depth``. See ``docs/formats.md``.
"""

from __future__ import annotations

from pathlib import Path

import importlib
from typing import TYPE_CHECKING

from tofnet.errors import DataError, located
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording, VelocitySource

# Readers load on first use: ``tofnet.io.spec`` (and ``tofnet compile``) should not pay
# for compiling the numba event parser.
_LAZY = {
    "read_calibration": "calibration", "write_calibration": "calibration",
    "read_depth": "depth", "write_depth": "depth",
    "attach_sidecars": "ecd", "read_ecd": "ecd", "read_imu": "ecd", "write_ecd": "ecd",
    "events_from_columns": "events", "read_events_npy": "events", "read_events_txt": "events",
    "write_events_npy": "events", "write_events_txt": "events",
    "Trajectory": "groundtruth", "VelocitySamples": "groundtruth", "read_groundtruth": "groundtruth",
    "read_velocity_samples": "groundtruth", "write_groundtruth": "groundtruth",
    "write_velocity_samples": "groundtruth",
}

if TYPE_CHECKING:
    from tofnet.io.calibration import read_calibration, write_calibration  # noqa: F401
    from tofnet.io.depth import read_depth, write_depth  # noqa: F401
    from tofnet.io.ecd import attach_sidecars, read_ecd, read_imu, write_ecd  # noqa: F401
    from tofnet.io.events import (events_from_columns, read_events_npy, read_events_txt,  # noqa: F401
                                  write_events_npy, write_events_txt)
    from tofnet.io.groundtruth import (Trajectory, VelocitySamples, read_groundtruth,  # noqa: F401
                                       read_velocity_samples, write_groundtruth, write_velocity_samples)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f"tofnet.io.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'tofnet.io' has no attribute {name!r}")


#: File suffixes ``read_recording`` accepts besides a folder.
EVENT_SUFFIXES = (".txt", ".npy", ".npz")


def read_recording(path: str | Path, sensor_size: tuple[int, int] | None = None) -> Recording:
    """Read a recording from an ECD folder, an events ``.txt`` or a ``.npy``/``.npz`` events file.

    For a file, ``calib.txt``, ``groundtruth.txt``, ``imu.txt`` and ``sensor_size.txt``
    in the same folder are read too, and ``<stem>_depth.npy`` as the true depth per
    event. ``sensor_size`` (width, height px), when given, overrides ``sensor_size.txt``.
    Raises ``DataError`` for a missing path, an unknown format or no events.
    """
    from tofnet.io.ecd import attach_sidecars, read_ecd
    from tofnet.io.events import read_events_npy, read_events_txt

    path = Path(path)
    if not path.exists():
        raise DataError(located(path, None, "no such file or folder; expected an ECD folder or an events "
                                            "file (.txt, .npy, .npz)"))
    if path.is_dir():
        recording = read_ecd(path)
    elif path.suffix in EVENT_SUFFIXES:
        notes: list[str] = []
        events = read_events_txt(path, notes) if path.suffix == ".txt" else read_events_npy(path)
        recording = attach_sidecars(Recording(events=events, source=str(path), notes=notes), path.parent,
                                    gt_depth_name=f"{path.stem}_depth.npy")
    else:
        raise DataError(located(path, None, f"unknown recording format {path.suffix!r}; expected an ECD folder "
                                            "or an events file (.txt, .npy, .npz)"))
    if len(recording.events) == 0:
        raise DataError(located(path, None, "no events"))
    if sensor_size is not None:
        from tofnet.events import sensor_size_problem
        width, height = (int(v) for v in sensor_size)
        problem = sensor_size_problem(width, height)
        if problem:
            raise DataError(f"sensor size: {problem}")
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
