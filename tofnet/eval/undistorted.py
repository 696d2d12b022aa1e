"""The recording as a network with an ``UndistortProcess`` sees it, for matching its estimates to ground truth.

An undistorting network's estimate at pixel ``(x, y)`` is at an undistorted pixel, so its
triggering event is found among the recording's events moved to their undistorted pixels
with the same lens and rounding as the process (``kernels.undistort.pixel_targets``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tofnet.io.recording import Intrinsics, Recording
from tofnet.kernels.undistort import pixel_targets, undistortion_map


def lens_from_summary(undistortion: dict) -> tuple[Intrinsics, tuple[int, int]]:
    """The lens and sensor size a depth file's summary (``tofnet run``: ``undistortion``) records."""
    fx, fy, cx, cy = undistortion["intrinsics"]
    lens = Intrinsics(fx, fy, cx, cy, distortion=tuple(undistortion["coefficients"]),
                      distortion_model=undistortion["model"])
    return lens, tuple(int(v) for v in undistortion["sensor_size"])


def undistorted_recording(recording: Recording, lens: Intrinsics, sensor_size: tuple[int, int]) -> Recording:
    """``recording`` with every event at its undistorted pixel (``sensor_size`` image, width x height px);
    events that leave the image are removed, with their ground truth, so ``gt_depth`` stays aligned.
    Calibration, poses and IMU are kept."""
    targets = pixel_targets(undistortion_map(lens, sensor_size))
    events = recording.events
    x, y = events["x"].astype(np.int64), events["y"].astype(np.int64)
    height, width = targets.shape
    inside = (x < width) & (y < height)
    target = np.full(len(events), -1, dtype=np.int64)
    target[inside] = targets[y[inside], x[inside]]
    keep = target >= 0
    moved = events[keep].copy()
    moved["x"], moved["y"] = target[keep] % width, target[keep] // width
    gt = recording.gt_depth[keep] if recording.gt_depth is not None else None
    return dataclasses.replace(recording, events=moved, gt_depth=gt)
