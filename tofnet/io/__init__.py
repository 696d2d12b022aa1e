"""Recordings in, depth out: event files, ECD folders, ground truth, calibration, depth files.

``read_recording`` is the one entry point the CLI and examples use (``open_recording``
for reading in chunks, ``source``); the format modules underneath are ``ecd``,
``events``, ``arrays``, ``groundtruth``, ``calibration``, ``depth``, and, through
optional extras, ``aedat``, ``prophesee``, ``hdf5``, ``hdf5_datasets``, ``rosbag``;
``detect`` recognises them; ``convert``, ``maps`` and ``ply`` write. See ``docs/formats.md``.
"""

from __future__ import annotations

from pathlib import Path

import importlib
from typing import TYPE_CHECKING

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
    "open_recording": "source", "EventSource": "source", "detect_format": "detect", "FORMATS": "detect",
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
EVENT_SUFFIXES = (".txt", ".npy", ".npz", ".aedat4", ".raw", ".dat", ".es", ".h5", ".hdf5", ".bag")


def read_recording(path: str | Path, sensor_size: tuple[int, int] | None = None, *,
                   columns: str | tuple[str, ...] | None = None, topics: dict[str, str] | None = None,
                   progress=None, window=None, intrinsics: Intrinsics | None = None,
                   calib: str | Path | None = None, camera: str | None = None,
                   allow_external: bool = False, side: str | None = None, rectify: bool = False) -> Recording:
    """Read a whole recording in any format ``tofnet.io.detect`` knows (see ``docs/formats.md``).

    An ECD folder, an events ``.txt``, ``.npy``/``.npz`` arrays, AEDAT4, Prophesee RAW/DAT,
    Event Stream, HDF5 (DSEC/TUM-VIE, MVSEC, M3ED) or a ROS1 or ROS 2 bag, recognised by content.
    For a file, ``calib.txt``, ``groundtruth.txt``, ``imu.txt`` and ``sensor_size.txt``
    in the same folder fill in what the file does not hold, and ``<stem>_depth.npy``
    gives the true depth per event of text/numpy files. ``sensor_size`` (width, height
    px) overrides the recording's; ``columns`` orders a plain ``(n, 4)`` array; ``topics``
    overrides ROS bag topics; ``progress(done, total)`` is called as events are read;
    ``window`` (``tofnet.io.window.TimeWindow``) reads only that time window; ``intrinsics``
    or a calibration file ``calib`` (``camera`` picks one of several) replace the camera's.
    ``allow_external`` lets an HDF5 file keep data in other files (refused otherwise).
    ``side`` and ``rectify`` apply to dataset sequence folders (``tofnet.io.sequences``).
    Raises ``DataError`` for a missing path, an unknown format or no events. For large
    files, ``open_recording`` reads in chunks.
    """
    from tofnet.io.source import open_recording

    with open_recording(path, sensor_size=sensor_size, columns=columns, topics=topics,
                        window=window, intrinsics=intrinsics, calib=calib, camera=camera,
                        allow_external=allow_external, side=side, rectify=rectify) as source:
        return source.read(progress)


__all__ = [
    "read_recording", "open_recording", "EventSource", "detect_format", "FORMATS", "read_ecd", "write_ecd", "read_imu", "attach_sidecars",
    "read_events_txt", "write_events_txt", "read_events_npy", "write_events_npy", "events_from_columns",
    "read_calibration", "write_calibration",
    "Trajectory", "VelocitySamples", "read_groundtruth", "write_groundtruth", "read_velocity_samples",
    "write_velocity_samples",
    "read_depth", "write_depth",
    "Recording", "Intrinsics", "VelocitySource", "ConstantVelocity",
]
