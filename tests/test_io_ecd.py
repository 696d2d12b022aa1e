"""ECD recording folders and ``read_recording`` on folders, .txt, .npy and .npz files."""

from __future__ import annotations

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.events import make_events
from tofnet.io import read_ecd, read_recording, write_ecd, write_events_npy
from tofnet.io.groundtruth import Trajectory
from tofnet.io.recording import Intrinsics

# The slider_depth files, a few lines each, as ECD publishes them.
SLIDER = {
    "events.txt": "0.003811000 96 133 0\n0.003820001 127 171 1\n0.003836001 4 160 0\n1.500000000 200 15 1\n",
    "calib.txt": "335.419462958 335.352935775 129.924663379 92.1864667189 -0.138592767408 0.0933736664192 "
                 "-0.000335586987532 0.000173720158228 0.0\n",
    "groundtruth.txt": "0.000000000 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000 1.000000\n"
                       "1.000000000 0.320000 0.000000 0.000000 0.000000 0.000000 0.000000 1.000000\n"
                       "2.000000000 0.640000 0.000000 0.000000 0.000000 0.000000 0.000000 1.000000\n",
    "imu.txt": "0.005811000 0.3 -9.7 0.1 0.04 0.05 -0.01\n0.006811000 0.2 -9.8 0.1 0.03 0.05 -0.02\n",
    "images.txt": "0.000000000 images/frame_00000000.png\n",
}


@pytest.fixture
def slider(tmp_path):
    folder = tmp_path / "slider_depth"
    folder.mkdir()
    for name, text in SLIDER.items():
        (folder / name).write_text(text)
    return folder


def test_read_slider_depth_folder(slider):
    recording = read_ecd(slider)
    assert recording.events["t"].tolist() == [3811, 3820, 3836, 1500000]
    assert recording.events["p"].tolist() == [0, 1, 0, 1]
    assert recording.intrinsics.fx == 335.419462958 and recording.intrinsics.cy == 92.1864667189
    assert len(recording.intrinsics.distortion) == 5
    assert isinstance(recording.trajectory, Trajectory)
    assert np.allclose(recording.trajectory.velocity_at(np.array([0.5, 1.5])), [[0.32, 0, 0]] * 2)
    assert recording.imu.shape == (2, 7) and recording.imu.dtype == np.float64
    assert recording.imu[1, 2] == -9.8
    assert recording.sensor_size is None and recording.gt_depth is None
    assert read_recording(slider).events.tolist() == recording.events.tolist()


def test_optional_files_may_be_missing(slider):
    for name in ("calib.txt", "groundtruth.txt", "imu.txt"):
        (slider / name).unlink()
    recording = read_ecd(slider)
    assert recording.intrinsics is None and recording.trajectory is None and recording.imu is None
    assert len(recording.events) == 4


def test_write_ecd_round_trip_with_tofnet_extras(tmp_path):
    events = make_events([0, 10, 10, 2500], [1, 2, 300, 4], [5, 6, 7, 8], [1, 0, 1, 1])
    intrinsics = Intrinsics(200.0, 200.0, 119.5, 89.5)
    times = np.array([0.0, 0.001, 0.002])
    positions = np.array([[0, 0, 0], [0.001, 0, 0], [0.002, 0, 0.0005]])
    quaternions = np.array([[0, 0, 0, 1.0]] * 3)
    gt_depth = np.array([1.0, 2.5, np.nan, 0.75])
    write_ecd(tmp_path / "rec", events, intrinsics=intrinsics, times=times, positions=positions,
              quaternions=quaternions, sensor_size=(240, 180), gt_depth=gt_depth)
    recording = read_ecd(tmp_path / "rec")
    assert np.array_equal(recording.events, events)
    assert recording.intrinsics == intrinsics
    assert np.array_equal(recording.trajectory.times, times)
    assert np.array_equal(recording.trajectory.positions, positions)
    assert recording.sensor_size == (240, 180)
    assert np.array_equal(recording.gt_depth, gt_depth, equal_nan=True)


def test_write_ecd_without_poses_writes_no_groundtruth(tmp_path):
    events = make_events([0, 1], [1, 2], [1, 2], [0, 1])
    write_ecd(tmp_path / "rec", events, intrinsics=None)
    assert sorted(p.name for p in (tmp_path / "rec").iterdir()) == ["events.txt"]
    with pytest.raises(DataError, match="poses need all of times, positions and quaternions"):
        write_ecd(tmp_path / "rec2", events, intrinsics=None, times=[0.0, 1.0])


def test_ecd_errors(tmp_path, slider):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DataError, match="empty: no events.txt"):
        read_ecd(empty)
    (slider / "sensor_size.txt").write_text("240 180.5\n")
    with pytest.raises(DataError, match="sensor_size.txt:1: expected positive whole numbers"):
        read_ecd(slider)
    (slider / "sensor_size.txt").write_text("240 180\n")
    np.save(slider / "events_depth.npy", np.ones(3))
    with pytest.raises(DataError, match="events_depth.npy: expected 4 depths"):
        read_ecd(slider)
    (slider / "events_depth.npy").unlink()
    (slider / "imu.txt").write_text("0.1 1 2 3\n")
    with pytest.raises(DataError, match="imu.txt:1: expected 7 columns"):
        read_ecd(slider)


def test_read_recording_txt_uses_sidecars_and_sensor_size_override(slider):
    (slider / "sensor_size.txt").write_text("240 180\n")
    recording = read_recording(slider / "events.txt")
    assert recording.intrinsics is not None and recording.trajectory is not None
    assert recording.sensor_size == (240, 180)
    assert read_recording(slider / "events.txt", sensor_size=(346, 260)).sensor_size == (346, 260)


@pytest.mark.parametrize("name", ["ev.npy", "ev.npz"])
def test_read_recording_numpy_with_sidecars(slider, name):
    events = make_events([5, 6, 7], [1, 2, 3], [4, 5, 6], [1, 1, 0])
    write_events_npy(slider / name, events)
    np.save(slider / "ev_depth.npy", np.array([1.0, 2.0, 3.0]))
    recording = read_recording(slider / name)
    assert np.array_equal(recording.events, events)
    assert recording.intrinsics.fx == 335.419462958
    assert recording.gt_depth.tolist() == [1.0, 2.0, 3.0]


def test_read_recording_errors(tmp_path, slider):
    with pytest.raises(DataError, match="nowhere: no such file or folder"):
        read_recording(tmp_path / "nowhere")
    (tmp_path / "rec.h5").write_bytes(b"")
    with pytest.raises(DataError, match="rec.h5: unknown recording format"):
        read_recording(tmp_path / "rec.h5")
    (slider / "events.txt").write_text("# no events here\n")
    with pytest.raises(DataError, match="events.txt: no events"):
        read_recording(slider)


def test_a_folder_of_event_files_is_not_a_recording_and_the_message_names_them(tmp_path):
    from tofnet.io import read_recording
    for name in ("b.raw", "a.aedat4", "notes.md"):
        (tmp_path / name).write_bytes(b"")
    with pytest.raises(DataError, match=r"no events.txt; .* it holds event files \('a.aedat4', 'b.raw'\): give one "
                                        r"of them \(tofnet batch runs many\)"):
        read_recording(tmp_path)


def test_an_events_file_with_commas_reads_as_one_with_spaces(tmp_path):
    from tofnet.io.events import read_events_txt
    (tmp_path / "spaces.txt").write_text("0.001 1 2 1\n0.002 3 4 0\n# note\n0.0035 5 6 1\n")
    (tmp_path / "commas.txt").write_text("0.001,1,2,1\n0.002, 3, 4, 0\n# note\n0.0035,5,6,1\n")
    spaces, commas = read_events_txt(tmp_path / "spaces.txt"), read_events_txt(tmp_path / "commas.txt")
    assert len(commas) == 3 and np.array_equal(commas, spaces)
