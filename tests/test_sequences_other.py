"""MVSEC, TUM-VIE and M3ED sequence folders, and one command per dataset layout, run and scored."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tests.optional import optional

h5py = optional("h5py")

from tofnet.cli import main  # noqa: E402
from tofnet.errors import DataError  # noqa: E402
from tofnet.io import detect_format, read_recording  # noqa: E402
from tofnet.io.layouts import sequence_name  # noqa: E402
from tofnet.testing_datasets import INTRINSICS, MAKERS, SIZE  # noqa: E402

VELOCITY = np.array([-0.5, 0.0, 0.0])


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("datasets")
    names = {"dsec": "zurich_city_00_a", "mvsec": "indoor_flying1", "tumvie": "mocap-desk2", "m3ed": "car_urban_day_1",
             "evimo2": "scene13_dyn_test_00_000000"}
    return {kind: make(root / names[kind], duration_s=2.2) for kind, make in MAKERS.items()}


@pytest.mark.parametrize("kind, name", [("mvsec", "indoor_flying1"), ("tumvie", "mocap-desk2"),
                                        ("m3ed", "car_urban_day_1"), ("evimo2", "scene13_dyn_test_00_000000")])
def test_each_folder_is_a_recording_with_its_calibration_and_poses(folders, kind, name):
    folder = folders[kind]
    assert detect_format(folder) == kind and sequence_name(folder) == name
    if kind != "evimo2":  # EVIMO2's events are three arrays of the folder, not a file named after the sequence
        events_file = next(p for p in folder.iterdir() if p.name.endswith(("_data.hdf5", "_data.h5", "-events_left.h5")))
        assert sequence_name(events_file) == name
    recording = read_recording(folder)
    assert recording.intrinsics.fx == INTRINSICS.fx and recording.sensor_size == SIZE
    t = recording.events["t"][len(recording.events) // 2: len(recording.events) // 2 + 1] * 1e-6
    np.testing.assert_allclose(recording.trajectory.velocity_at(t)[0], VELOCITY, atol=1e-4)
    if kind == "tumvie":
        assert recording.gt_depth is None and recording.frame_gt is None
        np.testing.assert_allclose(recording.imu[0, 1:], [0, 9.81, 0, 0, 0, 0])  # accel after the gyro in the file
    else:
        known = np.isfinite(recording.gt_depth)
        np.testing.assert_allclose(recording.gt_depth[known], 2.0)
        assert not known[recording.events["x"] == 0].any()


@pytest.mark.parametrize("kind, name", [("mvsec", "indoor_flying1_data.hdf5"), ("tumvie", "mocap-desk2-events_left.h5")])
def test_an_events_file_alone_takes_the_calibration_its_dataset_ships_beside_it(folders, kind, name):
    recording = read_recording(folders[kind] / name)
    assert recording.intrinsics.fx == INTRINSICS.fx and recording.trajectory is not None


def test_an_mvsec_file_without_its_calibration_reads_as_before(folders, tmp_path):
    folder = _copy(folders, "mvsec", tmp_path)
    shutil.rmtree(folder / "indoor_flying_calib")
    recording = read_recording(folder / "indoor_flying1_data.hdf5", side="right")
    assert recording.intrinsics is None and recording.gt_depth is None


def test_the_right_camera_gets_no_left_ground_truth(folders):
    recording = read_recording(folders["mvsec"], side="right")
    assert recording.gt_depth is None and recording.frame_gt is None
    assert "no davis/right poses or depth in indoor_flying1_gt.hdf5 (its depth images are davis/left's)" \
        in recording.notes, recording.notes
    assert any(note.startswith("poses and depth from") for note in read_recording(folders["mvsec"]).notes)


def _copy(folders, kind, tmp_path):
    return shutil.copytree(folders[kind], tmp_path / folders[kind].name)


def test_mvsec_without_its_calibration_names_what_is_missing(folders, tmp_path):
    folder = _copy(folders, "mvsec", tmp_path)
    shutil.rmtree(folder / "indoor_flying_calib")
    with pytest.raises(DataError, match="missing: the MVSEC calibration") as err:
        read_recording(folder)
    assert "\n" not in str(err.value)


def test_ground_truth_of_another_sequence_is_one_line(folders, tmp_path):
    folder = _copy(folders, "m3ed", tmp_path)
    with h5py.File(folder / "car_urban_day_1_depth_gt.h5", "r+") as h5:
        h5["ts"][...] = h5["ts"][...] + 3_600_000_000
    with pytest.raises(DataError, match=r"car_urban_day_1_depth_gt.h5: ground truth .* does not overlap the events"):
        read_recording(folder)


def test_tumvie_calibration_missing_several_or_without_mocap_calibration(folders, tmp_path):
    folder = _copy(folders, "tumvie", tmp_path)
    (folder / "mocap-imu-calibrationA.json").unlink()
    recording = read_recording(folder)
    assert recording.trajectory is None and any("mocap_data.txt not used" in n for n in recording.notes)
    shutil.copy(folder / "camera-calibrationA.json", folder / "camera-calibrationB.json")
    with pytest.raises(DataError, match="2 TUM-VIE camera calibration files"):
        read_recording(folder)
    for path in folder.glob("camera-calibration*.json"):
        path.unlink()
    with pytest.raises(DataError, match="missing: the TUM-VIE camera calibration"):
        read_recording(folder)


@pytest.mark.parametrize("text, message", [
    # a zero quaternion was a numpy warning, then "mocap_data.txt: pose 0: pose is not finite"
    ('{"value0": {"T_imu_marker": {"px": 0, "py": 0, "pz": 0, "qx": 0, "qy": 0, "qz": 0, "qw": 0}}}',
     "value0.T_imu_marker: the quaternion (qx, qy, qz, qw) is zero: no rotation"),
    ("{}", "value0.T_imu_marker: expected a pose {px, py, pz, qx, qy, qz, qw}"),  # "t1: ...: 'value0'"
    ("[1, 2]", "value0.T_imu_marker: expected a pose"),
    ('{"value0": {"T_imu_marker": {"px": 0, "py": 0, "pz": 0, "qx": 0, "qy": 0, "qz": 0, "qw": NaN}}}',
     "value0.T_imu_marker: expected finite numbers"),
])
def test_a_bad_tumvie_mocap_calibration_names_its_file(folders, tmp_path, text, message):
    import warnings
    folder = _copy(folders, "tumvie", tmp_path)
    (folder / "mocap-imu-calibrationA.json").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # and no numpy warning on the way
        with pytest.raises(DataError) as err:
            read_recording(folder)
    assert str(err.value).startswith(f"{folder / 'mocap-imu-calibrationA.json'}: {message}")


def test_a_folder_with_two_sequences_is_refused(folders, tmp_path):
    folder = _copy(folders, "m3ed", tmp_path)
    shutil.copy(folder / "car_urban_day_1_data.h5", folder / "car_urban_day_2_data.h5")
    with pytest.raises(DataError, match="2 files \\*_data.h5"):
        read_recording(folder)


@pytest.mark.parametrize("kind", ["dsec", "mvsec", "tumvie", "m3ed", "evimo2"])
@pytest.mark.parametrize("estimator", ["paper", "improved"])
def test_one_command_per_dataset_runs_a_2s_window_and_eval_scores_it(folders, kind, estimator, tmp_path, capsys):
    out = tmp_path / "depth.npz"
    motion = ["--velocity=-0.5,0,0"] if kind == "dsec" else []  # DSEC ships no poses
    assert main(["run", str(folders[kind]), "--estimator", estimator, "--start", "0.1s", "--duration", "2s",
                 "--out", str(out), *motion]) == 0
    capsys.readouterr()
    if kind == "tumvie":  # TUM-VIE ships poses, not depth
        assert main(["eval", str(folders[kind]), str(out), "--start", "0.1s", "--duration", "2s"]) != 0
        assert "no ground-truth depth" in capsys.readouterr().err
        return
    assert main(["eval", str(folders[kind]), str(out), "--start", "0.1s", "--duration", "2s", "--frames",
                 "interpolate", "--json", "-"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert "interpolated" in data["ground_truth"]
    assert data["matched"] > 1000 and data["median_rel_pct"] < 3.0
    assert data["mean_abs_cut10_m"] == pytest.approx(data["mean_abs_m"])


@pytest.mark.slow
def test_the_worked_commands_of_formats_md_datasets_run_as_written(tmp_path):
    """The ``sh`` block of docs/formats.md "Datasets", typed in a fresh folder."""
    import os
    import re
    import shlex
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    text = (root / "docs" / "formats.md").read_text(encoding="utf-8")
    section = text.split("## Datasets: sequence folders", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"^```sh\n(.*?)^```", section, flags=re.S | re.M).group(1)
    env = {**os.environ, "PYTHONPATH": str(root)}
    outputs = {}
    for line in block.splitlines():
        words = shlex.split(line.split("  #", 1)[0])
        if words[0] == "tofnet":
            words = [sys.executable, "-m", "tofnet", *words[1:]]
        elif words[:2] == ["python", "examples/dataset_folders.py"]:
            words = [sys.executable, str(root / words[1]), *words[2:]]
        done = subprocess.run(words, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{line}: {done.stderr[-400:]}"
        assert "Traceback" not in done.stderr
        outputs[line] = done.stdout
    evals = [out for line, out in outputs.items() if line.startswith("tofnet eval")]
    assert len(evals) == 4
    for out in evals:
        mean = float(re.search(r"abs error \[m\]\s+([\d.]+)", out).group(1))
        assert "ground truth" in out and mean < 0.1  # the plane is 2 m away
