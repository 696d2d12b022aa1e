"""Shared inputs for the format tests: a small textured recording with calibration and poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tofnet.io.groundtruth import Trajectory
from tofnet.io.recording import Intrinsics, Recording
from tofnet.testing import merge_events, moving_pattern, noise_events

SENSOR = (64, 48)
INTRINSICS = Intrinsics(60.0, 61.0, 31.5, 23.25, distortion=(-0.2, 0.05, 0.001, -0.0005, 0.0))
#: Absolute stamps (Unix epoch µs) as real cameras write them.
T0_US = 1_589_163_147_368_868


def pattern_recording(duration_us: int = 300_000) -> Recording:
    """Blobs sliding left and a little down, with noise; camera poses moving along +x while yawing."""
    events = merge_events(moving_pattern(SENSOR, (-40.0, 8.0), duration_us, seed=3, start_us=T0_US),
                          noise_events(SENSOR, 2.0, duration_us, seed=4, start_us=T0_US))
    times = T0_US * 1e-6 + np.linspace(-0.05, duration_us * 1e-6 + 0.05, 41)
    positions = np.column_stack([0.5 * (times - times[0]), 0.01 * (times - times[0]), np.zeros_like(times)])
    angles = 0.05 * (times - times[0])
    quaternions = np.column_stack([np.zeros_like(angles), np.sin(angles / 2), np.zeros_like(angles),
                                   np.cos(angles / 2)])
    imu = np.column_stack([times, np.tile([0.1, -9.8, 0.2, 0.01, 0.02, -0.03], (len(times), 1))])
    return Recording(events=events, intrinsics=INTRINSICS, trajectory=Trajectory(times, positions, quaternions),
                     sensor_size=SENSOR, imu=imu)


def faery_events(events: np.ndarray) -> np.ndarray:
    """``EVENT_DTYPE`` as faery's event dtype (t, x, y, on)."""
    import faery

    out = np.empty(len(events), dtype=faery.EVENTS_DTYPE)
    out["t"], out["x"], out["y"], out["on"] = events["t"], events["x"], events["y"], events["p"] == 1
    return out


class FullDiskEncoder:
    """Stands in for a faery encoder: leaves a partial file, then every write fails as faery reports a full disk."""

    def __init__(self, path, **kwargs):
        Path(path).write_bytes(b"partial")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def write(self, *packet):
        raise RuntimeError("No space left on device (os error 28)")


def strip_geometry(raw: Path, out: Path) -> None:
    """Copy a Prophesee RAW file to ``out`` without the header lines that give its sensor size."""
    data = Path(raw).read_bytes()
    end = 0
    while data.startswith(b"%", end):
        end = data.index(b"\n", end) + 1
    kept = [line for line in data[:end].splitlines(keepends=True)
            if not line.lower().startswith((b"% geometry", b"% format"))]
    Path(out).write_bytes(b"".join(kept) + data[end:])
