"""Dataset sequence folders (DSEC layout here) as recordings, and frame ground truth in ``tofnet eval``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.optional import optional

h5py = optional("h5py")

from tofnet.cli import main  # noqa: E402
from tofnet.errors import DataError  # noqa: E402
from tofnet.events import DEPTH_DTYPE, make_events  # noqa: E402
from tofnet.io import detect_format, read_recording  # noqa: E402
from tofnet.io.frames import FrameDepth, disparity_to_depth  # noqa: E402
from tofnet.io.layouts import sequence_name  # noqa: E402
from tofnet.testing_datasets import BASELINE_M, INTRINSICS, SIZE, make_dsec  # noqa: E402


@pytest.fixture(scope="module")
def dsec(tmp_path_factory):
    return make_dsec(tmp_path_factory.mktemp("dsec") / "zurich_city_00_a", duration_s=0.5)


def test_a_dsec_folder_is_a_recording_named_after_the_folder(dsec):
    assert detect_format(dsec) == "dsec"
    assert sequence_name(dsec) == "zurich_city_00_a"
    assert sequence_name(dsec / "events" / "left" / "events.h5") == "zurich_city_00_a"
    recording = read_recording(dsec)
    assert recording.intrinsics.fx == INTRINSICS.fx and recording.sensor_size == SIZE
    assert recording.events["t"][0] > 1_600_000_000_000_000  # t_offset applied
    known = np.isfinite(recording.gt_depth)
    # Disparity fx * b / 2 m (x256 in the PNG) back to 2 m; the two unknown columns give NaN.
    np.testing.assert_allclose(recording.gt_depth[known], 2.0, rtol=2e-3)
    assert not known[recording.events["x"] < 2].any() and known[recording.events["x"] >= 2].all()


def test_the_events_file_of_a_dsec_folder_reads_the_whole_sequence(dsec):
    recording = read_recording(dsec / "events" / "left" / "events.h5")
    assert recording.frame_gt is not None and np.isfinite(recording.gt_depth).any()
    with pytest.raises(DataError, match="--side right: the file is the left camera's"):
        read_recording(dsec / "events" / "left" / "events.h5", side="right")


def test_plan_names_come_from_the_sequence_folder(dsec):
    from tofnet.batch.plan import _recording_name
    assert _recording_name(dsec / "events" / "left" / "events.h5") == "zurich_city_00_a"
    assert _recording_name(dsec) == "zurich_city_00_a"


def test_disparity_to_depth_is_f_b_over_d():
    q = np.array([[1, 0, 0, -24], [0, 1, 0, -16], [0, 0, 0, 60.0], [0, 0, 1 / BASELINE_M, 0]])
    depth = disparity_to_depth(np.array([[0.0, 18.0, 36.0]]), q)
    assert np.isnan(depth[0, 0])
    np.testing.assert_allclose(depth[0, 1:], [60 * BASELINE_M / 18, 60 * BASELINE_M / 36])
    q[3, 2] = -q[3, 2]  # the baseline written with the other sign
    np.testing.assert_allclose(disparity_to_depth(np.array([[18.0]]), q), [[60 * BASELINE_M / 18]])


def _frames(pixel_map=None):
    images = [np.arange(12, dtype=float).reshape(3, 4) + 1, np.arange(12, dtype=float).reshape(3, 4) * 3 + 1]
    return FrameDepth(np.array([0, 100_000]), lambda k: images[k], (3, 4), "test", pixel_map=pixel_map)


def test_frames_nearest_interpolated_and_through_a_pixel_map():
    frames = _frames()
    t, x, y = np.array([10_000, 90_000, 25_000]), np.array([1, 1, 2]), np.array([0, 0, 1])
    np.testing.assert_allclose(frames.at(t, x, y), [2.0, 4.0, 7.0])
    np.testing.assert_allclose(frames.at(t, x, y, interpolate=True), [2.2, 3.8, 7.0 * 0.75 + 19.0 * 0.25])
    assert np.isnan(frames.at(np.array([300_000]), np.array([0]), np.array([0]))[0])  # > 0.1 s from any frame
    yy, xx = np.mgrid[0:3, 0:4].astype(float)
    shifted = _frames(np.stack([xx + 1, yy], axis=-1))  # rectified x = raw x + 1
    got = shifted.at(np.zeros(3, dtype=np.int64), np.array([0, 2, 3]), np.array([0, 2, 0]))
    np.testing.assert_allclose(got[:2], [2.0, 12.0])
    assert np.isnan(got[2])  # mapped outside the frame


def _shifted_map(dsec, folder):
    """A copy of the DSEC folder whose rectification map moves every event 1 px right (the last column leaves)."""
    import shutil
    shutil.copytree(dsec, folder)
    y, x = np.mgrid[0:SIZE[1], 0:SIZE[0]].astype(np.float32)
    with h5py.File(folder / "events" / "left" / "rectify_map.h5", "w") as h5:
        h5.create_dataset("rectify_map", data=np.stack([x + 1, y], axis=-1))
    return folder


def test_rectify_moves_events_through_the_map_and_counts_those_left_out(dsec, tmp_path):
    folder = _shifted_map(dsec, tmp_path / "seq")
    raw = read_recording(folder)
    rectified = read_recording(folder, rectify=True)
    keep = raw.events["x"] < SIZE[0] - 1
    np.testing.assert_array_equal(rectified.events["x"], raw.events["x"][keep] + 1)
    np.testing.assert_array_equal(rectified.events["t"], raw.events["t"][keep])
    assert any(f"{int((~keep).sum()):,} events fell outside" in n for n in rectified.notes)
    # Raw pixels look the ground truth up through the map: raw column 0 is rectified column 1, unknown.
    assert np.isnan(raw.gt_depth[raw.events["x"] == 0]).all() and np.isfinite(raw.gt_depth[raw.events["x"] == 1]).all()
    assert np.isnan(rectified.gt_depth[rectified.events["x"] == 1]).all()


def test_rectified_events_left_out_are_counted_by_every_streaming_read(dsec, tmp_path, capsys):
    from tofnet.io import open_recording
    folder = _shifted_map(dsec, tmp_path / "seq")
    raw = read_recording(folder)
    window = raw.events["t"] < raw.events["t"][0] + 300_000
    left_out = f"{int((raw.events['x'][window] == SIZE[0] - 1).sum()):,} events fell outside the rectified image"
    with open_recording(folder, rectify=True) as source:  # chunks, read twice: each read counts its own
        for _ in range(2):
            assert sum(len(c) for c in source.chunks(1000)) == int((raw.events["x"] < SIZE[0] - 1).sum())
            assert left_out_of(source.notes) == [int((raw.events["x"] == SIZE[0] - 1).sum())]
    out, report = tmp_path / "depth.npz", tmp_path / "run.json"
    assert main(["run", str(folder), "--rectify", "--velocity=-0.5,0,0", "--duration", "300ms", "--out", str(out),
                 "--json", str(report)]) == 0  # streams: the file says its sensor size
    assert any(left_out in n for n in json.loads(report.read_text())["notes"])
    assert left_out in capsys.readouterr().out
    assert main(["info", str(folder), "--rectify", "--duration", "300ms"]) == 0
    assert left_out in capsys.readouterr().out


def left_out_of(notes):
    """The counts of the rectification notes among ``notes`` (one per source)."""
    return [int(n.split(": ")[-1].split(" ")[0].replace(",", "")) for n in notes if "fell outside" in n]


@pytest.mark.parametrize("damage, expected", [
    (lambda f: (f / "calibration" / "cam_to_cam.yaml").unlink(), "cam_to_cam.yaml: missing"),
    (lambda f: (f / "disparity" / "timestamps.txt").write_text("1600000000000000\n1600000000100000\n"),
     "2 timestamps for 5 disparity maps"),
    (lambda f: (f / "disparity" / "timestamps.txt").write_text("".join(f"{i * 100_000 + 1}\n" for i in range(5))),
     "the ground truth of another sequence?"),
    (lambda f: (f / "disparity" / "timestamps.txt").unlink(), "timestamps.txt: missing"),
    (lambda f: (f / "events" / "left" / "rectify_map.h5").unlink(), "rectify_map.h5: missing"),
])
def test_a_folder_that_is_almost_a_dsec_sequence_is_one_line_naming_the_file(dsec, tmp_path, damage, expected):
    import shutil
    folder = tmp_path / "seq"
    shutil.copytree(dsec, folder)
    damage(folder)
    with pytest.raises(DataError) as err:
        read_recording(folder)
    assert expected in str(err.value) and "\n" not in str(err.value)


def test_a_folder_with_dsec_calibration_but_no_events_names_the_events_file(tmp_path):
    (tmp_path / "seq" / "calibration").mkdir(parents=True)
    (tmp_path / "seq" / "calibration" / "cam_to_cam.yaml").write_text("intrinsics: {}\n")
    with pytest.raises(DataError, match=r"events[/\\]left[/\\]events.h5: missing"):
        detect_format(tmp_path / "seq")


def test_right_side_and_options_outside_sequences(dsec, tmp_path):
    with pytest.raises(DataError, match="events.h5: missing: the right events"):
        read_recording(dsec, side="right")
    (tmp_path / "events.txt").write_text("0.0 1 1 1\n")
    with pytest.raises(DataError, match="--side and --rectify apply to dataset sequence folders"):
        read_recording(tmp_path / "events.txt", rectify=True)


def test_eval_scores_estimates_against_the_frames_at_their_own_pixel():
    from tofnet.eval.metrics import evaluate_arrays
    events = make_events([10_000, 10_100, 10_200], [0, 1, 2], [0, 0, 0], [1, 1, 1])
    depth = np.zeros(3, DEPTH_DTYPE)
    depth["step"], depth["x"], depth["y"], depth["z"] = 2, [0, 1, 2], 0, [2.5, 12.0, 25.0]
    frames = FrameDepth(np.array([0, 50_000]), lambda k: np.array([[2.0, 11.0, 21.0]]), (1, 3), "test")
    wrong_event_gt = np.full(3, 99.0)  # frames win over the per-event depth
    result = evaluate_arrays(depth, events, wrong_event_gt, t0_us=10_000, timestep_us=1000, latency_steps=2,
                             frame_gt=frames, window_s=0)
    np.testing.assert_allclose(result.matches.gt, [2.0, 11.0, 21.0])
    assert result.errors.mean_abs_m == pytest.approx((0.5 + 1.0 + 4.0) / 3)
    assert result.cutoffs == pytest.approx({"mean_abs_cut10_m": 0.5, "mean_abs_cut20_m": 0.75,
                                            "mean_abs_cut30_m": 5.5 / 3})
    assert "2 depth images (nearest in time)" in result.table()


def test_run_and_eval_a_dsec_folder_from_the_command_line(dsec, tmp_path, capsys):
    out = tmp_path / "depth.npz"
    assert main(["run", str(dsec), "--velocity=-0.5,0,0", "--duration", "400ms", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["eval", str(dsec), str(out), "--duration", "400ms", "--json", "-"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["ground_truth"].startswith("5 disparity maps")
    assert data["matched"] > 100 and data["median_rel_pct"] < 5
    assert data["mean_abs_cut10_m"] == pytest.approx(data["mean_abs_m"])  # every true depth is 2 m
    assert main(["plot", "error", str(dsec), str(out), "--rectify", "--out", str(tmp_path / "error.png")]) == 0
    assert (tmp_path / "error.png").stat().st_size > 1000


def test_a_batch_over_the_events_files_of_dsec_folders_scores_them_by_folder_name(tmp_path):
    import csv
    optional("distributed")
    make_dsec(tmp_path / "zurich_city_00_a", duration_s=0.5)
    make_dsec(tmp_path / "zurich_city_01_a", duration_s=0.5, depth_m=3.0)
    (tmp_path / "plan.yaml").write_text('recordings:\n  - {glob: "*/events/left/events.h5", velocity: [-0.5, 0, 0]}\n'
                                        "keep: [metrics]\n")
    assert main(["batch", str(tmp_path / "plan.yaml"), "--workers", "1", "--quiet"]) == 0
    with open(tmp_path / "plan-results" / "results.csv", newline="") as handle:
        rows = {row["recording_name"]: row for row in csv.DictReader(handle)}
    assert sorted(rows) == ["zurich_city_00_a", "zurich_city_01_a"]
    for row in rows.values():
        assert row["status"] == "ok" and 0 < float(row["mean_abs_cut10_m"]) < 0.1
        assert row["mean_abs_cut10_m"] == row["mean_abs_m"]


def test_eval_reads_a_sequence_as_its_run_did(dsec, tmp_path, capsys):
    """A run with --rectify records it in the depth file; eval without the flag rectifies too (it matched few
    estimates, their pixels being rectified and the events not), and says so."""
    folder = _shifted_map(dsec, tmp_path / "seq")
    out = tmp_path / "depth.npz"
    assert main(["run", str(folder), "--rectify", "--velocity=-0.5,0,0", "--duration", "300ms", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["eval", str(folder), str(out), "--json", str(tmp_path / "a.json")]) == 0
    assert "note: events rectified, as the run read them (--rectify, from" in capsys.readouterr().err
    assert main(["eval", str(folder), str(out), "--rectify", "--json", str(tmp_path / "b.json")]) == 0
    assert json.loads((tmp_path / "a.json").read_text()) == json.loads((tmp_path / "b.json").read_text())
