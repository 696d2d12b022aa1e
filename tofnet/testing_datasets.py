"""Small dataset sequence folders in the published layouts (DSEC, MVSEC, TUM-VIE, M3ED), for tests and docs.

Each ``make_*`` writes a folder with a textured plane at ``depth_m`` seen by a camera moving
at ``velocity`` (m/s, camera frame; ``tofnet.testing.flowing_pattern``), the dataset's
calibration and its ground truth (disparity maps, depth images or poses) of that plane.
``python examples/dataset_folders.py OUT`` makes one of each.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tofnet.io.recording import Intrinsics
from tofnet.testing import camera_flow, flowing_pattern

#: Sensor of the fixtures (px) and their camera.
SIZE = (48, 32)
INTRINSICS = Intrinsics(60.0, 60.0, 24.0, 16.0)
#: Stereo baseline of the DSEC fixture (m).
BASELINE_M = 0.6
#: The DSEC fixture's clock starts here (µs), as DSEC's ``t_offset`` does.
DSEC_T_OFFSET_US = 1_600_000_000_000_000


def plane_events(depth_m: float, velocity, duration_s: float, start_us: int = 0, seed: int = 0) -> np.ndarray:
    """``EVENT_DTYPE`` events of a textured plane at ``depth_m`` (``SIZE``, ``INTRINSICS``)."""
    flow = camera_flow(INTRINSICS, depth_m, velocity, (0.0, 0.0, 0.0))
    return flowing_pattern(SIZE, flow, int(duration_s * 1e6), kind="blobs", scale_px=3.0, seed=seed,
                           sample_us=1000, start_us=start_us)


def _columns(h5, group: str, events: np.ndarray, t: np.ndarray) -> None:
    h5.create_dataset(f"{group}/x", data=events["x"].astype(np.uint16))
    h5.create_dataset(f"{group}/y", data=events["y"].astype(np.uint16))
    h5.create_dataset(f"{group}/t", data=t)
    h5.create_dataset(f"{group}/p", data=events["p"].astype(np.uint8))


def _camera_matrix(k: Intrinsics) -> list[list[float]]:
    return [[k.fx, 0.0, k.cx], [0.0, k.fy, k.cy], [0.0, 0.0, 1.0]]


def make_dsec(folder: str | Path, *, depth_m: float = 2.0, velocity=(-0.5, 0.0, 0.0), duration_s: float = 2.2,
              rate_hz: float = 10.0) -> Path:
    """A DSEC sequence folder (events/left, calibration/cam_to_cam.yaml, disparity/) of a plane."""
    import h5py

    from tofnet.io.frames import write_png16

    folder = Path(folder)
    events = plane_events(depth_m, velocity, duration_s)
    (folder / "events" / "left").mkdir(parents=True)
    with h5py.File(folder / "events" / "left" / "events.h5", "w") as h5:
        _columns(h5, "events", events, events["t"].astype(np.uint32))
        ms = np.searchsorted(events["t"], np.arange(0, int(events["t"][-1]) // 1000 + 1) * 1000)
        h5.create_dataset("ms_to_idx", data=ms.astype(np.uint64))
        h5.create_dataset("t_offset", data=np.int64(DSEC_T_OFFSET_US))
    y, x = np.mgrid[0:SIZE[1], 0:SIZE[0]].astype(np.float32)
    with h5py.File(folder / "events" / "left" / "rectify_map.h5", "w") as h5:
        h5.create_dataset("rectify_map", data=np.stack([x, y], axis=-1))  # rectified = raw: no distortion
    k = INTRINSICS
    cameras = {name: {"camera_matrix": [k.fx, k.fy, k.cx, k.cy], "distortion_coeffs": [0.0, 0.0, 0.0, 0.0],
                      "distortion_model": "radtan", "resolution": list(SIZE)} for name in ("cam0", "cam1", "cam2", "cam3")}
    cameras.update({f"camRect{i}": {"camera_matrix": [k.fx, k.fy, k.cx, k.cy], "resolution": list(SIZE)}
                    for i in range(4)})
    q = [[1.0, 0.0, 0.0, -k.cx], [0.0, 1.0, 0.0, -k.cy], [0.0, 0.0, 0.0, k.fx], [0.0, 0.0, 1.0 / BASELINE_M, 0.0]]
    (folder / "calibration").mkdir()
    import yaml
    (folder / "calibration" / "cam_to_cam.yaml").write_text(yaml.safe_dump(
        {"intrinsics": cameras, "disparity_to_depth": {"cams_03": q, "cams_12": q}}))
    (folder / "disparity" / "event").mkdir(parents=True)
    disparity = np.full((SIZE[1], SIZE[0]), round(k.fx * BASELINE_M / depth_m * 256))
    disparity[:, :2] = 0  # unknown, as at the border of DSEC's maps
    times = np.arange(0, duration_s, 1.0 / rate_hz)
    for i in range(len(times)):
        write_png16(folder / "disparity" / "event" / f"{2 * i:06d}.png", disparity)
    (folder / "disparity" / "timestamps.txt").write_text(
        "".join(f"{DSEC_T_OFFSET_US + int(round(t * 1e6))}\n" for t in times))
    return folder


def depth_frames(depth_m: float, duration_s: float, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Depth images ``(n, H, W)`` of the plane (NaN in the first column) and their times (s)."""
    times = np.arange(0, duration_s, 1.0 / rate_hz)
    images = np.full((len(times), SIZE[1], SIZE[0]), depth_m, dtype=np.float32)
    images[:, :, 0] = np.nan
    return images, times


__all__ = ["SIZE", "INTRINSICS", "BASELINE_M", "plane_events", "make_dsec", "depth_frames"]
