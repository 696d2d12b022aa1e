"""Small dataset sequence folders in the published layouts (DSEC, MVSEC, TUM-VIE, M3ED, EVIMO2), for tests and docs.

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
    """Depth images ``(n, H, W)`` of the plane (NaN in the first column) and their times (s from 0)."""
    times = np.arange(0, duration_s, 1.0 / rate_hz)
    images = np.full((len(times), SIZE[1], SIZE[0]), depth_m, dtype=np.float32)
    images[:, :, 0] = np.nan
    return images, times


def camera_poses(velocity, times_s: np.ndarray) -> np.ndarray:
    """Camera-to-world 4x4 transforms of a camera moving at ``velocity`` (m/s) without turning."""
    poses = np.tile(np.eye(4), (len(times_s), 1, 1))
    poses[:, :3, 3] = np.asarray(times_s)[:, None] * np.asarray(velocity, dtype=np.float64)[None]
    return poses


#: MVSEC's clock: seconds since the epoch; the fixture starts here (s).
MVSEC_T0_S = 1_506_117_900.0


def make_mvsec(folder: str | Path, *, name: str = "indoor_flying1", depth_m: float = 2.0,
               velocity=(-0.5, 0.0, 0.0), duration_s: float = 2.2, rate_hz: float = 20.0) -> Path:
    """An MVSEC sequence folder: ``<name>_data.hdf5``, ``<name>_gt.hdf5`` (poses, raw depth images) and
    ``<scene>_calib/camchain-imucam-<scene>.yaml``."""
    import h5py
    import yaml

    folder = Path(folder)
    folder.mkdir(parents=True)
    events = plane_events(depth_m, velocity, duration_s)
    rows = np.column_stack([events["x"], events["y"], MVSEC_T0_S + events["t"] * 1e-6,
                            np.where(events["p"] > 0, 1, -1)]).astype(np.float64)
    with h5py.File(folder / f"{name}_data.hdf5", "w") as h5:
        h5.create_dataset("davis/left/events", data=rows)
        h5.create_dataset("davis/right/events", data=rows)
    images, times = depth_frames(depth_m, duration_s, rate_hz)
    with h5py.File(folder / f"{name}_gt.hdf5", "w") as h5:
        h5.create_dataset("davis/left/depth_image_raw", data=images)
        h5.create_dataset("davis/left/depth_image_raw_ts", data=MVSEC_T0_S + times)
        pose_times = np.arange(0, duration_s + 0.05, 0.01)
        h5.create_dataset("davis/left/pose", data=camera_poses(velocity, pose_times))
        h5.create_dataset("davis/left/pose_ts", data=MVSEC_T0_S + pose_times)
    scene = name.rstrip("0123456789")
    k = INTRINSICS
    camera = {"camera_model": "pinhole", "intrinsics": [k.fx, k.fy, k.cx, k.cy], "distortion_model": "equidistant",
              "distortion_coeffs": [0.0, 0.0, 0.0, 0.0], "resolution": list(SIZE)}
    (folder / f"{scene}_calib").mkdir()
    (folder / f"{scene}_calib" / f"camchain-imucam-{scene}.yaml").write_text(
        yaml.safe_dump({"cam0": camera, "cam1": camera}))
    return folder


def _basalt_pose(matrix=None) -> dict:
    return {"px": 0.0, "py": 0.0, "pz": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0}


def make_tumvie(folder: str | Path, *, name: str = "mocap-desk2", depth_m: float = 2.0, velocity=(-0.5, 0.0, 0.0),
                duration_s: float = 2.2) -> Path:
    """A TUM-VIE sequence folder: ``<name>-events_left.h5``, ``camera-calibrationA.json``,
    ``mocap-imu-calibrationA.json`` and ``<name>-vi_gt_data/{mocap_data,imu_data}.txt``."""
    import h5py

    folder = Path(folder)
    folder.mkdir(parents=True)
    t0 = 1_600_000_000_000_000
    events = plane_events(depth_m, velocity, duration_s)
    with h5py.File(folder / f"{name}-events_left.h5", "w") as h5:
        _columns(h5, "events", events, t0 + events["t"].astype(np.int64))
        ms = np.searchsorted(events["t"], np.arange(0, int(events["t"][-1]) // 1000 + 1) * 1000)
        h5.create_dataset("ms_to_idx", data=ms.astype(np.uint64))
    k = INTRINSICS
    kb4 = {"camera_type": "kb4", "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
                                                "k1": 0.0, "k2": 0.0, "k3": 0.0, "k4": 0.0}}
    frame = {"camera_type": "kb4", "intrinsics": {"fx": 700.0, "fy": 700.0, "cx": 512.0, "cy": 512.0,
                                                  "k1": 0.0, "k2": 0.0, "k3": 0.0, "k4": 0.0}}
    (folder / "camera-calibrationA.json").write_text(json.dumps({"value0": {
        "T_imu_cam": [_basalt_pose()] * 4, "intrinsics": [frame, frame, kb4, kb4],
        "resolution": [[1024, 1024], [1024, 1024], list(SIZE), list(SIZE)]}}))
    (folder / "mocap-imu-calibrationA.json").write_text(json.dumps({"value0": {"T_imu_marker": _basalt_pose()}}))
    gt = folder / f"{name}-vi_gt_data"
    gt.mkdir()
    times = np.arange(0, duration_s + 0.05, 0.005)
    positions = times[:, None] * np.asarray(velocity)[None]
    (gt / "mocap_data.txt").write_text("# timestamp[us] tx ty tz qx qy qz qw\n" + "".join(
        f"{t0 + int(round(t * 1e6))} {p[0]:.9f} {p[1]:.9f} {p[2]:.9f} 0 0 0 1\n" for t, p in zip(times, positions)))
    (gt / "imu_data.txt").write_text("# timestamp[us] gx gy gz ax ay az\n" + "".join(
        f"{t0 + int(round(t * 1e6))} 0 0 0 0 9.81 0\n" for t in times))
    return folder


def make_m3ed(folder: str | Path, *, name: str = "car_urban_day_1", depth_m: float = 2.0,
              velocity=(-0.5, 0.0, 0.0), duration_s: float = 2.2, rate_hz: float = 10.0) -> Path:
    """An M3ED sequence folder: ``<name>_data.h5`` (prophesee/left with its calib) and ``<name>_depth_gt.h5``."""
    import h5py

    folder = Path(folder)
    folder.mkdir(parents=True)
    events = plane_events(depth_m, velocity, duration_s)
    k = INTRINSICS
    with h5py.File(folder / f"{name}_data.h5", "w") as h5:
        _columns(h5, "prophesee/left", events, events["t"].astype(np.int64))
        ms = np.searchsorted(events["t"], np.arange(0, int(events["t"][-1]) // 1000 + 1) * 1000)
        h5.create_dataset("prophesee/left/ms_map_idx", data=ms.astype(np.uint64))
        h5.create_dataset("prophesee/left/calib/intrinsics", data=[k.fx, k.fy, k.cx, k.cy])
        h5.create_dataset("prophesee/left/calib/distortion_coeffs", data=[0.0, 0.0, 0.0, 0.0])
        h5.create_dataset("prophesee/left/calib/distortion_model", data="equidistant")
        h5.create_dataset("prophesee/left/calib/resolution", data=list(SIZE))
    images, times = depth_frames(depth_m, duration_s, rate_hz)
    with h5py.File(folder / f"{name}_depth_gt.h5", "w") as h5:
        h5.create_dataset("ts", data=np.round(times * 1e6).astype(np.int64))
        h5.create_dataset("Cn_T_C0", data=np.linalg.inv(camera_poses(velocity, times)))
        h5.create_dataset("depth/prophesee/left", data=images)
    return folder


def evimo2_camera(k: Intrinsics, size: tuple[int, int]) -> dict:
    """The camera as EVIMO2's ``meta['meta']`` holds it (``dist_model`` with ``k1..k4 p1 p2``)."""
    model = k.distortion_model if k.distortion else "radtan"
    values = dict(zip(("k1", "k2", "p1", "p2", "k3"), k.distortion or (0.0,) * 5)) if model == "radtan" else \
        {**dict(zip(("k1", "k2", "k3", "k4"), k.distortion)), "p1": 0.0, "p2": 0.0}
    return {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "dist_model": model, "k4": 0.0, **values,
            "res_x": size[0], "res_y": size[1], "ros_time_offset": 1606265321.445115}


def write_evimo2(folder: str | Path, events: np.ndarray, t_s: np.ndarray, camera: dict, poses, depth, *,
                 column_arrays: bool = False, lost: tuple[int, ...] = (), first_id: int = 0) -> Path:
    """An EVIMO2 v2 sequence folder as the dataset's packaging writes it (``np.save``, ``np.savez`` with the
    metadata dictionary pickled). ``t_s`` the events' times (s, float32 or float64), ``poses`` ``(times s,
    positions, quaternions qx qy qz qw)`` camera to world, ``depth`` ``(times s, images uint16 mm)``; ``lost``
    pose samples carry no camera pose; ``column_arrays`` writes ``t`` and ``p`` as ``(n, 1)``; the frames' ids start
    at ``first_id`` (a sub-sequence after the first) while the depth images are numbered from 0, as EVIMO's are."""
    folder = Path(folder)
    folder.mkdir(parents=True)
    p = events["p"].astype(np.uint8)
    np.save(folder / "dataset_events_t.npy", t_s[:, None] if column_arrays else t_s)
    np.save(folder / "dataset_events_xy.npy", np.column_stack([events["x"], events["y"]]).astype(np.uint16))
    np.save(folder / "dataset_events_p.npy", p[:, None] if column_arrays else p)
    meta = _evimo_meta(float(t_s[0]), camera, poses, depth[0], lost, first_id)
    k_matrix = [[camera["fx"], 0.0, camera["cx"]], [0.0, camera["fy"], camera["cy"]], [0.0, 0.0, 1.0]]
    np.savez(folder / "dataset_info.npz", K=np.array(k_matrix), D=np.zeros(4), discretization=np.float64(0.01),
             index=np.zeros(len(depth[0]), np.int64), meta=meta)
    images = depth[1]
    np.savez_compressed(folder / "dataset_depth.npz", **{f"depth_{k:010d}": image for k, image in enumerate(images)})
    np.savez_compressed(folder / "dataset_mask.npz", **{f"mask_{k:010d}": np.zeros_like(image)
                                                        for k, image in enumerate(images)})
    return folder


def write_evimo_npz(path: str | Path, events: np.ndarray, t_s: np.ndarray, camera: dict, poses, depth) -> Path:
    """An EVIMO / EVIMO2 v1 sequence file: ``events`` ``(n, 4)`` (t s, x, y, p), ``depth`` ``(frames, H, W)`` mm,
    ``meta`` (pickled), ``K``, ``D``, ``index``, ``discretization`` (arguments as ``write_evimo2``)."""
    path = Path(path)
    rows = np.column_stack([t_s, events["x"], events["y"], events["p"]]).astype(np.float32)  # as pydvs writes them
    k_matrix = [[camera["fx"], 0.0, camera["cx"]], [0.0, camera["fy"], camera["cy"]], [0.0, 0.0, 1.0]]
    np.savez_compressed(path, events=rows, depth=np.asarray(depth[1]), mask=np.zeros_like(depth[1]), classical=None,
                        meta=_evimo_meta(float(t_s[0]), camera, poses, depth[0], ()), K=np.array(k_matrix),
                        D=np.zeros(4), index=np.zeros(len(depth[0]), np.int64), discretization=np.float64(0.01))
    return path


def write_evimo_txt(folder: str | Path, events: np.ndarray, camera: dict, poses, frame_times) -> Path:
    """EVIMO's TXT layout: ``events.txt`` (``t x y p``, seconds), ``meta.txt`` (the metadata as a Python literal) and
    an ``img/`` folder (its depth PNGs are not written: tofnet does not read them)."""
    from tofnet.io.events import write_events_txt

    folder = Path(folder)
    (folder / "img").mkdir(parents=True)
    write_events_txt(folder / "events.txt", events)
    (folder / "meta.txt").write_text(repr(_evimo_meta(float(events["t"][0]) * 1e-6, camera, poses, frame_times, ())))
    return folder


def _evimo_meta(t0_s: float, camera: dict, poses, frame_times, lost, first_id: int = 0) -> dict:
    """EVIMO's metadata dictionary: the camera, its Vicon poses (``lost``: samples without it), the frames."""
    def pose(ts, position, q):
        return {"ts": float(ts), "pos": {"t": dict(zip("xyz", map(float, position))),
                                         "q": dict(zip("xyzw", map(float, q))), "rpy": {"r": 0.0, "p": 0.0, "y": 0.0}}}

    full = [{"ts": float(ts), "cam": pose(ts, position, q)} for ts, position, q in zip(*poses)]
    for k in lost:
        full[k] = {"ts": full[k]["ts"], "5": full[k]["cam"]}  # an object's pose only (EVIMO itself always writes 'cam')
    frames = [{"id": first_id + k, "ts": float(ts), "gt_frame": f"depth_mask_{first_id + k}.png",
               "cam": full[0]["cam"]} for k, ts in enumerate(frame_times)]
    return {"frames": frames, "full_trajectory": full, "meta": camera,
            "imu": {"/prophesee/left/imu": [{"ts": t0_s, "angular_velocity": {"x": 0.0, "y": 0.0, "z": 0.0},
                                             "linear_acceleration": {"x": 0.0, "y": 0.0, "z": 9.81}}]}}


def make_evimo2(folder: str | Path, *, depth_m: float = 2.0, velocity=(-0.5, 0.0, 0.0), duration_s: float = 2.2,
                rate_hz: float = 60.0) -> Path:
    """An EVIMO2 v2 sequence folder (events, ``dataset_info.npz``, ``dataset_depth.npz``) of a plane."""
    events = plane_events(depth_m, velocity, duration_s)
    times = np.arange(0, duration_s + 0.05, 0.005)  # Vicon at 200 Hz
    quaternions = np.tile([0.0, 0.0, 0.0, 1.0], (len(times), 1))
    images, frame_times = depth_frames(depth_m, duration_s, rate_hz)
    millimetres = np.nan_to_num(images * 1000.0, nan=0.0).round().astype(np.uint16)  # 0: unknown
    return write_evimo2(folder, events, events["t"] * 1e-6, evimo2_camera(INTRINSICS, SIZE),
                        (times, camera_poses(velocity, times)[:, :3, 3], quaternions), (frame_times, millimetres))


#: Each layout's fixture maker.
MAKERS = {"dsec": make_dsec, "mvsec": make_mvsec, "tumvie": make_tumvie, "m3ed": make_m3ed, "evimo2": make_evimo2}

__all__ = ["SIZE", "INTRINSICS", "BASELINE_M", "MAKERS", "plane_events", "make_dsec", "make_mvsec", "make_tumvie",
           "make_m3ed", "make_evimo2", "write_evimo2", "write_evimo_npz", "write_evimo_txt", "evimo2_camera", "depth_frames", "camera_poses"]
