"""EVIMO2 v2 sequence folders (NPZ layout): events, camera, poses, depth frames; the pickled metadata read
without running anything from the file."""

import os

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.io.detect import detect_format
from tofnet.io.source import open_recording

from tofnet.io.recording import Intrinsics
from tofnet.testing_datasets import evimo2_camera
from tofnet.testing_datasets import make_evimo2, write_evimo_npz
from tofnet.testing_datasets import write_evimo2 as write_evimo2_folder

from formats_helpers import INTRINSICS, SENSOR, T0_US, pattern_recording

START_US = 500_000  # EVIMO2's times are seconds from the sequence's start


@pytest.fixture(scope="module")
def recording():
    return pattern_recording(duration_us=200_000)


def write_evimo2(folder, recording, *, float32=False, column_arrays=False, lost=(), model="radtan", first_id=0):
    """The recording (events, camera, poses) as an EVIMO2 sequence, with depth frames of 1.5 m at 60 Hz (0,
    unknown, in the first 8 columns) from 0.52 s; its times start at ``START_US``."""
    events = recording.events
    t = (events["t"] - T0_US + START_US) * 1e-6
    intrinsics = INTRINSICS if model == "radtan" else \
        Intrinsics(INTRINSICS.fx, INTRINSICS.fy, INTRINSICS.cx, INTRINSICS.cy, (0.1, -0.01, 0.002, -0.0003), model)
    traj = recording.trajectory
    depth = np.full((11, SENSOR[1], SENSOR[0]), 1500, dtype=np.uint16)
    depth[:, :, :8] = 0
    return write_evimo2_folder(folder, events, t.astype(np.float32) if float32 else t, evimo2_camera(intrinsics, SENSOR),
                               (traj.times - (T0_US - START_US) * 1e-6, traj.positions, traj.quaternions),
                               (0.52 + np.arange(11) / 60, depth), column_arrays=column_arrays, lost=lost,
                               first_id=first_id)


def _expected_events(recording):
    events = recording.events.copy()
    events["t"] = events["t"] - T0_US + START_US
    return events


def test_folder_reads_events_camera_poses_and_true_depth(tmp_path, recording):
    folder = write_evimo2(tmp_path / "samsung_mono" / "imo" / "eval" / "scene13_dyn_test_00_000000", recording,
                          lost=(3, 4))
    assert detect_format(folder) == "evimo2"
    from tofnet.io.layouts import sequence_name
    assert sequence_name(folder) == "scene13_dyn_test_00_000000-samsung_mono"  # EVIMO2's cameras share seq names
    source = open_recording(folder)
    read = source.read()
    assert np.array_equal(read.events, _expected_events(recording))
    assert read.intrinsics == INTRINSICS and read.sensor_size == SENSOR
    assert source.detail == "EVIMO2 v2 sequence, samsung_mono"
    traj = recording.trajectory
    assert len(read.trajectory.times) == len(traj.times) - 2  # the two samples without the camera
    assert np.allclose(read.trajectory.positions, np.delete(traj.positions, [3, 4], axis=0))
    assert any("2 of 41 pose samples without the camera's pose" in note for note in source.notes)
    assert any(note.startswith("samsung_mono: the polarity is the opposite") for note in source.notes)
    # true depth: 1.5 m where the frames know it (not the first 8 columns), near a frame in time
    t_s = read.events["t"] * 1e-6
    known = (read.events["x"] >= 8) & (t_s >= 0.52 - 0.05) & (t_s <= 0.52 + 10 / 60 + 0.05)
    assert known.any() and (~known).any()
    assert np.allclose(read.gt_depth[known], 1.5) and np.isnan(read.gt_depth[~known]).all()
    assert {"dataset_mask.npz", "dataset_classical.npz"} & set(source.streams) == {"dataset_mask.npz"}
    assert "imu" in source.streams


def test_float32_column_arrays_and_equidistant_lens(tmp_path, recording):
    folder = write_evimo2(tmp_path / "seq", recording, float32=True, column_arrays=True, model="equidistant")
    read = open_recording(folder).read()
    expected = _expected_events(recording)
    # float32 seconds hold these times (< 1 s) to well under a microsecond
    assert np.array_equal(read.events["t"], expected["t"]) and np.array_equal(read.events["x"], expected["x"])
    assert read.intrinsics.distortion_model == "equidistant"
    assert read.intrinsics.distortion == (0.1, -0.01, 0.002, -0.0003)


def test_time_window_reads_only_its_events(tmp_path, recording):
    folder = write_evimo2(tmp_path / "seq", recording)
    from tofnet.io.window import parse_window

    source = open_recording(folder)
    source.set_window(parse_window("50ms", "50ms"))
    read = source.read()
    expected = _expected_events(recording)
    first = expected["t"][0]
    keep = (expected["t"] >= first + 50_000) & (expected["t"] < first + 100_000)
    assert np.array_equal(read.events, expected[keep]) and source.n_events == int(keep.sum())
    assert len(read.gt_depth) == len(read.events)


def test_pickled_metadata_cannot_run_code(tmp_path, recording):
    folder = write_evimo2(tmp_path / "seq", recording)
    marker = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    meta = np.empty((), dtype=object)
    meta[()] = {"meta": Payload()}
    np.savez(folder / "dataset_info.npz", meta=meta)
    with pytest.raises(DataError, match=r"dataset_info.npz\[meta\]: not a readable object array: refers to "
                                         r"(posix|os)\.system: not read"):
        open_recording(folder)
    assert not marker.exists()


@pytest.mark.parametrize("change, message", [
    (lambda f: (f / "dataset_events_p.npy").unlink(), r"dataset_events_p.npy: missing: a file of the EVIMO2"),
    (lambda f: np.save(f / "dataset_events_xy.npy", np.zeros((3, 2), np.uint16)), r"the event arrays do not match"),
    (lambda f: np.savez(f / "dataset_info.npz", K=np.eye(3)), r"dataset_info.npz: no array 'meta'"),
    (lambda f: np.save(f / "dataset_events_p.npy", (np.load(f / "dataset_events_t.npy") * 10).astype(np.uint8)),
     r"dataset_events_p.npy: polarities up to 7; expected 0/1 \(EVIMO2's first NPZ release wrote the time there"),
    (lambda f: np.savez(f / "dataset_info.npz", meta={"meta": {"fx": "x"}}),
     r"dataset_info.npz\[meta\].meta.fx: expected a finite number, got 'x'"),
    (lambda f: np.savez(f / "dataset_info.npz", meta={"meta": {"fx": 0.0, "fy": 1.0, "cx": 1.0, "cy": 1.0,
                                                              "res_x": 4, "res_y": 4}}),
     r"\[meta\].meta: focal lengths must be positive"),
])
def test_broken_folders_are_one_line_errors(tmp_path, recording, change, message):
    folder = write_evimo2(tmp_path / "seq", recording)
    change(folder)
    with pytest.raises(DataError, match=message):
        open_recording(folder).read()


def test_run_and_eval_on_the_folder(tmp_path, recording, capsys):
    import json

    folder = write_evimo2(tmp_path / "seq", recording)
    out = tmp_path / "depth.npz"
    assert main(["run", str(folder), "--out", str(out), "--quiet"]) == 0
    assert main(["info", str(folder)]) == 0
    text = capsys.readouterr().out
    assert "EVIMO2 v2 sequence" in text and "dataset_mask.npz" in text
    assert main(["eval", str(folder), str(out), "--json", "-"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert "EVIMO2 depth frames" in data["ground_truth"] and data["matched"] > 0


def test_depth_images_not_keyed_by_frame_id_are_taken_in_order(tmp_path, recording):
    folder = write_evimo2(tmp_path / "seq", recording)
    depth = np.full((SENSOR[1], SENSOR[0]), 2500, dtype=np.uint16)
    np.savez_compressed(folder / "dataset_depth.npz", **{f"depth_{k + 7:010d}": depth for k in range(11)})
    source = open_recording(folder)
    read = source.read()
    assert any("named after neither the frames' positions nor their ids: taken in order" in note for note in source.notes)
    known = np.isfinite(read.gt_depth)
    assert known.any() and np.allclose(read.gt_depth[known], 2.5)
    np.savez_compressed(folder / "dataset_depth.npz", **{f"depth_{k:010d}": depth for k in range(3)})  # 3 of 11
    source = open_recording(folder)
    assert any("8 ground-truth frames of the metadata have no depth image" in note for note in source.notes)


def test_an_evimo_v1_sequence_file_gives_its_camera_poses_and_depth_frames(tmp_path, capsys):
    import json

    from tofnet.io import read_recording

    plane = read_recording(make_evimo2(tmp_path / "v2", duration_s=1.0))  # a plane 2 m away, as a v2 folder
    v1 = write_evimo_npz(tmp_path / "scene15_dyn_test_01.npz", plane.events, plane.events["t"] * 1e-6,
                         evimo2_camera(plane.intrinsics, plane.sensor_size),
                         (plane.trajectory.times, plane.trajectory.positions, plane.trajectory.quaternions),
                         (plane.frame_gt.times_us * 1e-6, (2000 * np.ones((len(plane.frame_gt), 32, 48))).astype(np.uint16)))
    source = open_recording(v1)
    read = source.read()
    assert np.array_equal(read.events, plane.events) and read.intrinsics == plane.intrinsics
    assert read.sensor_size == plane.sensor_size and len(read.trajectory.times) == len(plane.trajectory.times)
    assert np.allclose(read.gt_depth[np.isfinite(read.gt_depth)], 2.0) and np.isfinite(read.gt_depth).mean() > 0.9
    assert any(note == "not read: arrays mask, classical, index, discretization of scene15_dyn_test_01.npz" for note in source.notes)
    out = tmp_path / "depth.npz"
    assert main(["run", str(v1), "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["eval", str(v1), str(out), "--json", "-"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert "EVIMO depth frames" in data["ground_truth"]
    assert data["matched"] > 1000 and data["median_rel_pct"] < 5.0  # the plane at 2 m, the camera's own poses


def test_an_npz_says_which_arrays_it_does_not_read(tmp_path):
    path = tmp_path / "events.npz"
    np.savez(path, t=np.arange(5, dtype=np.int64), x=np.zeros(5, np.uint16), y=np.zeros(5, np.uint16),
             p=np.ones(5, np.int8), frames=np.zeros((2, 4, 4)))
    source = open_recording(path)
    assert "not read: array frames of events.npz" in source.notes


def test_evimo_txt_layout_gives_the_camera_and_poses_of_its_meta_txt(tmp_path, recording):
    from tofnet.io.calibration import write_calibration
    from tofnet.io.window import parse_window
    from tofnet.testing_datasets import write_evimo_txt

    traj = recording.trajectory
    folder = write_evimo_txt(tmp_path / "txt", recording.events, evimo2_camera(INTRINSICS, SENSOR),
                             (traj.times, traj.positions, traj.quaternions), [0.5])
    write_calibration(folder / "calib.txt", Intrinsics(1.0e3, 1.0e3, 1.0, 1.0))  # meta.txt's camera wins over it
    for options in ({}, {"window": parse_window("0s", "50ms")}):
        source = open_recording(folder, **options)
        assert source.intrinsics == INTRINSICS and source.sensor_size == SENSOR
        assert options or np.allclose(source.trajectory.positions, traj.positions)  # a window cuts the poses
        assert "camera and poses from meta.txt (EVIMO's TXT layout)" in source.notes
        assert any(note.startswith("not read: img, EVIMO's depth and mask frames") for note in source.notes)
    (folder / "meta.txt").write_text("{'meta': __import__('os').system('true')}")
    with pytest.raises(DataError, match=r"meta.txt: not a Python literal \(EVIMO's metadata dictionary\)"):
        open_recording(folder)



def test_a_later_sub_sequence_pairs_its_depth_images_by_position_not_id(tmp_path, recording):
    folder = write_evimo2(tmp_path / "seq", recording, first_id=1234)  # ids 1234..., images depth_0000000000...
    images = dict(np.load(folder / "dataset_depth.npz"))
    images["depth_0000000003"] = np.full_like(images["depth_0000000003"], 2500)  # frame 3 (id 1237) is another depth
    del images["depth_0000000010"]  # and the last frame's image is missing
    np.savez_compressed(folder / "dataset_depth.npz", **images)
    source = open_recording(folder)
    read = source.read()
    frame_of = np.rint((read.events["t"] * 1e-6 - 0.52) * 60).astype(int)  # the nearest frame of each event
    near = (np.abs(read.events["t"] * 1e-6 - (0.52 + frame_of / 60)) < 0.008) & (read.events["x"] >= 8)
    assert np.allclose(read.gt_depth[near & (frame_of == 3)], 2.5)
    assert np.allclose(read.gt_depth[near & (frame_of >= 0) & (frame_of <= 9) & (frame_of != 3)], 1.5)
    assert any("1 ground-truth frames of the metadata have no depth image" in note for note in source.notes)


def test_meta_txt_is_parsed_as_a_literal_only():
    import ast

    from tofnet.io.evimo_meta import camera, parse_literal

    for text in ("{'a': 1, 'b': [1, 2.5, -3e-2, 18446744073709551615], 'c': {'d': None, 'e': True}, 'f': (1, 2)}",
                 "[(1, 2), (3,)]", "{'s': 'it\\'s', \"t\": \"x\"}", "{}"):
        assert parse_literal(text, "m") == ast.literal_eval(text)
    for text, why in (("{'a': __import__('os')}", "unexpected text"), ("[" * 100 + "]" * 100, "nested more than 64"),
                      ("{'a' 1}", "expected a colon"), ("[1, 2", "the text ends inside a bracket"), ("1 2", "a second value"),
                      # a container as a key: a tuple's was looked for among the values (StopIteration)
                      *((key, "a dictionary key must be a string, a number, True, False or None") for key in
                        ("{'meta': {(1, 2): 3}}", "{(): 1}", "{[1]: 2}", "{'a': {{}: 1}}", "{(1, (2,)): 3}"))):
        with pytest.raises(DataError, match=f"m: not a Python literal .* at character [0-9,]+: {why}"):
            parse_literal(text, "m")
    with pytest.raises(DataError, match=r"w.meta.fx: expected a finite number, got int"):
        camera(parse_literal("{'meta': {'fx': 1" + "0" * 400 + "}}", "m"), "w")
