"""HDF5 layouts (DSEC/TUM-VIE, MVSEC, M3ED) with fixtures written by h5py, and compressed datasets."""

import subprocess
import sys

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.io import read_recording
from tofnet.io.source import open_recording
from optional import optional

h5py = optional("h5py")

from formats_helpers import SENSOR, pattern_recording  # noqa: E402


@pytest.fixture(scope="module")
def recording():
    return pattern_recording()


def _dsec(path, events, *, t_dtype="<u4", compression=None, **extra):
    """DSEC's events.h5: t µs (uint32) after t_offset, ms_to_idx."""
    t_offset = int(events["t"][0])
    with h5py.File(path, "w") as f:
        for name, data in (("t", (events["t"] - t_offset).astype(t_dtype)), ("x", events["x"]),
                           ("y", events["y"]), ("p", events["p"])):
            f.create_dataset(f"events/{name}", data=data, compression=compression, **extra)
        f.create_dataset("t_offset", data=np.int64(t_offset))
        f.create_dataset("ms_to_idx", data=np.searchsorted(events["t"] - t_offset, np.arange(0, 400) * 1000))


def test_dsec_layout(tmp_path, recording):
    path = tmp_path / "events.h5"
    _dsec(path, recording.events, compression="gzip")
    source = open_recording(path)
    assert source.detail == "DSEC layout" and source.n_events == len(recording.events)
    assert "ms_to_idx" in source.streams
    read = source.read()
    assert np.array_equal(read.events, recording.events)


def test_dsec_calibration_yaml_gives_equidistant_intrinsics(tmp_path, recording):
    folder = tmp_path / "zurich_city_00_a" / "events" / "left"
    folder.mkdir(parents=True)
    _dsec(folder / "events.h5", recording.events)
    (tmp_path / "zurich_city_00_a" / "calibration").mkdir()
    (tmp_path / "zurich_city_00_a" / "calibration" / "cam_to_cam.yaml").write_text(
        "intrinsics:\n  cam0:\n    camera_matrix: [555.6, 555.1, 342.3, 218.0]\n"
        "    distortion_coeffs: [-0.04, 0.01, -0.003, 0.0006]\n    distortion_model: equidistant\n"
        "    resolution: [640, 480]\n  camRect0:\n    camera_matrix: [1, 1, 1, 1]\n")
    source = open_recording(folder / "events.h5")
    assert source.intrinsics.distortion_model == "equidistant"
    assert source.intrinsics.distortion == (-0.04, 0.01, -0.003, 0.0006) and source.intrinsics.fx == 555.6
    assert source.sensor_size == (640, 480)


def test_tofnet_writer_round_trip_with_calibration_poses_imu(tmp_path, recording):
    from tofnet.io.hdf5 import write_hdf5

    path = tmp_path / "out.h5"
    chunks = [recording.events[:3000], recording.events[3000:]]
    assert write_hdf5(path, chunks, recording) == len(recording.events)
    read = read_recording(path)
    assert np.array_equal(read.events, recording.events)
    assert read.intrinsics == recording.intrinsics and read.sensor_size == SENSOR
    assert np.array_equal(read.trajectory.times, recording.trajectory.times)
    assert np.array_equal(read.imu, recording.imu)
    with h5py.File(path) as f:
        t, ms_to_idx = f["events/t"][()], f["ms_to_idx"][()]
    for k, index in enumerate(ms_to_idx[:-1]):
        assert t[index] >= k * 1000 and (index == 0 or t[index - 1] < k * 1000)
    assert ms_to_idx[-1] == len(t)


def test_mvsec_layout_with_ground_truth_file(tmp_path, recording):
    events = recording.events
    rows = np.column_stack([events["x"], events["y"], events["t"] * 1e-6, np.where(events["p"] == 1, 1.0, -1.0)])
    with h5py.File(tmp_path / "indoor_flying1_data.hdf5", "w") as f:
        f.create_dataset("davis/left/events", data=rows)
        f.create_dataset("davis/left/image_raw", data=np.zeros((2, SENSOR[1], SENSOR[0]), np.uint8))
        f.create_dataset("davis/left/imu", data=recording.imu[:, 1:])
        f.create_dataset("davis/left/imu_ts", data=recording.imu[:, 0])
        f.create_dataset("davis/right/events", data=rows[:10])
    traj = recording.trajectory
    depth_times = events["t"][0] * 1e-6 + np.array([0.0, 0.1, 0.2])
    images = np.full((3, SENSOR[1], SENSOR[0]), 2.0, np.float32) + np.arange(3)[:, None, None]
    images[:, 0, :] = np.nan  # no depth on the top row
    with h5py.File(tmp_path / "indoor_flying1_gt.hdf5", "w") as f:
        poses = np.tile(np.eye(4), (len(traj.times), 1, 1))
        positions, rotations = traj.pose_at(traj.times)
        poses[:, :3, :3], poses[:, :3, 3] = rotations, positions
        f.create_dataset("davis/left/pose", data=poses)
        f.create_dataset("davis/left/pose_ts", data=traj.times)
        f.create_dataset("davis/left/depth_image_raw", data=images)
        f.create_dataset("davis/left/depth_image_raw_ts", data=depth_times)
    source = open_recording(tmp_path / "indoor_flying1_data.hdf5")
    assert source.detail.startswith("MVSEC") and source.sensor_size == SENSOR
    assert "davis/right" in source.streams
    read = source.read()
    # MVSEC stores seconds as float64: Unix-epoch µs survive to within 1 µs of rounding
    assert np.abs(read.events["t"] - events["t"]).max() <= 1
    assert np.array_equal(read.events[["x", "y", "p"]], events[["x", "y", "p"]])
    assert np.allclose(read.trajectory.velocity_at(traj.times[5:10]), traj.velocity_at(traj.times[5:10]))
    assert np.array_equal(read.imu, recording.imu)
    nearest = np.argmin(np.abs(read.events["t"][:, None] * 1e-6 - depth_times[None, :]), axis=1)
    expected = np.where(read.events["y"] == 0, np.nan, 2.0 + nearest)
    expected[np.abs(read.events["t"] * 1e-6 - depth_times[nearest]) > 0.1] = np.nan
    assert np.array_equal(read.gt_depth, expected, equal_nan=True)


def test_m3ed_layout_with_depth_ground_truth(tmp_path, recording):
    events = recording.events
    with h5py.File(tmp_path / "car_urban_day_data.h5", "w") as f:
        for name in ("t", "x", "y", "p"):
            f.create_dataset(f"prophesee/left/{name}", data=events[name].astype("<i8" if name == "t" else
                                                                                  events.dtype[name]))
        f.create_dataset("prophesee/left/ms_map_idx", data=np.zeros(3, np.uint64))
        f.create_dataset("prophesee/left/calib/intrinsics", data=[600.0, 601.0, 32.0, 24.0])
        f.create_dataset("prophesee/left/calib/distortion_coeffs", data=[0.1, -0.01, 0.002, -0.0003])
        f.create_dataset("prophesee/left/calib/distortion_model", data="equidistant")
        f.create_dataset("prophesee/left/calib/resolution", data=list(SENSOR))
        f.create_dataset("ovc/ts", data=np.zeros(2))
    times_us = events["t"][0] + np.array([0, 150_000, 300_000])
    with h5py.File(tmp_path / "car_urban_day_depth_gt.h5", "w") as f:
        f.create_dataset("ts", data=times_us)
        c_to_w = np.tile(np.eye(4), (3, 1, 1))
        c_to_w[:, 0, 3] = [0.0, 0.15, 0.3]  # 1 m/s along x
        f.create_dataset("Cn_T_C0", data=np.linalg.inv(c_to_w))
        f.create_dataset("depth/prophesee/left", data=np.full((3, SENSOR[1], SENSOR[0]), 4.0, np.float32))
    source = open_recording(tmp_path / "car_urban_day_data.h5")
    assert source.intrinsics.distortion_model == "equidistant" and source.sensor_size == SENSOR
    assert "ovc" in source.streams
    read = source.read()
    assert np.array_equal(read.events, events)
    assert np.allclose(read.trajectory.velocity_at(np.array([times_us[1] * 1e-6])), [[1.0, 0.0, 0.0]])
    assert np.all(read.gt_depth == 4.0)


def test_unknown_layout_names_what_it_found(tmp_path):
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.create_dataset("images", data=np.zeros(3))
    with pytest.raises(DataError, match="other.h5: no event datasets.*found 'images'"):
        read_recording(tmp_path / "other.h5")


def test_time_going_back_names_the_event(tmp_path, recording):
    events = recording.events.copy()
    events["t"][700] = events["t"][699] - 1
    _dsec(tmp_path / "events.h5", events, t_dtype="<i8")
    with pytest.raises(DataError, match="time goes back"):
        read_recording(tmp_path / "events.h5")


def test_filter_without_plugin_names_the_extra(tmp_path, recording, monkeypatch):
    from tofnet.io import hdf5_checks

    _dsec(tmp_path / "events.h5", recording.events, compression="gzip")
    # Pretend gzip needs a plugin and hdf5plugin is not installed.
    monkeypatch.setattr(hdf5_checks, "_BUILTIN_FILTERS", set())
    monkeypatch.setattr("h5py.h5z.filter_avail", lambda code: False)
    monkeypatch.setitem(sys.modules, "hdf5plugin", None)
    with pytest.raises(DataError) as caught:
        read_recording(tmp_path / "events.h5")
    message = str(caught.value)
    assert "\n" not in message and "events/t" in message and "pip install \"tofnet[hdf5plugin]\"" in message


def test_blosc_compressed_file(tmp_path, recording):
    hdf5plugin = optional("hdf5plugin")
    path = tmp_path / "events.h5"
    _dsec(path, recording.events, **hdf5plugin.Blosc(cname="zstd"))
    # A fresh interpreter has not registered the filter yet: tofnet loads hdf5plugin itself.
    code = ("import numpy as np, sys; from tofnet.io import read_recording; "
            f"e = read_recording({str(path)!r}).events; print(len(e), int(e['t'][0]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == [str(len(recording.events)), str(int(recording.events["t"][0]))]
    hidden = ("import sys; sys.modules['hdf5plugin'] = None; from tofnet.cli import main; "
              f"sys.exit(main(['info', {str(path)!r}, '--quiet']))")
    run = subprocess.run([sys.executable, "-c", hidden], capture_output=True, text=True)
    assert run.returncode == 2 and "tofnet[hdf5plugin]" in run.stderr and run.stderr.count("\n") == 1
