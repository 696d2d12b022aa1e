"""``tofnet eval`` end to end on small files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.events import DEPTH_DTYPE, make_events
from tofnet.io import write_depth, write_ecd
from tofnet.io.recording import Intrinsics

META = {"t0_us": 10_000, "timestep_us": 1000, "latency_steps": 2}


@pytest.fixture
def files(tmp_path):
    """Four events (true depths 1, 2, 5, 4 m) and three estimates of the first three."""
    events = make_events([10_000, 10_100, 10_200, 160_000], [0, 1, 2, 3], [0, 0, 0, 0], [1, 1, 1, 1])
    gt = np.array([1.0, 2.0, 5.0, 4.0])
    write_ecd(tmp_path / "rec", events, intrinsics=Intrinsics(10, 10, 2, 2), sensor_size=(4, 1), gt_depth=gt)
    write_ecd(tmp_path / "nogt", events, intrinsics=None)
    depth = np.empty(3, DEPTH_DTYPE)
    depth["step"] = 2
    depth["t"] = 10_000 + 3 * 1000
    depth["x"], depth["y"], depth["z"] = [0, 1, 2], 0, [1.1, 1.8, 4.0]
    write_depth(tmp_path / "depth.npz", depth, **META)
    write_depth(tmp_path / "depth.csv", depth, **META)
    return tmp_path


def test_eval_prints_the_papers_errors_and_writes_json(files, capsys):
    out = files / "m" / "metrics.json"
    assert main(["eval", str(files / "rec"), str(files / "depth.npz"), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "abs error [m]" in text and "0.433" in text and "0.200" in text
    assert "rel error [%]" in text and "13.33" in text and "10.00" in text
    assert "coverage 75.00 %" in text
    data = json.loads(out.read_text())
    assert data["mean_abs_m"] == pytest.approx(1.3 / 3)
    assert data["median_rel_pct"] == pytest.approx(10.0)
    assert (data["events_in"], data["estimates"], data["unmatched"]) == (4, 3, 0)
    assert [w["events_in"] for w in data["windows"]] == [3, 1]  # 100 ms windows from t0
    assert data["windows"][1]["mean_abs_m"] is None


def test_eval_json_to_stdout_and_no_windows(files, capsys):
    assert main(["eval", str(files / "rec"), str(files / "depth.npz"), "--json", "-", "--window", "0"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["windows"] == [] and data["coverage"] == pytest.approx(0.75)


def test_eval_without_ground_truth_says_what_it_needs(files, capsys):
    assert main(["eval", str(files / "nogt"), str(files / "depth.npz")]) == 2
    err = capsys.readouterr().err
    assert "ground-truth depth" in err and "events_depth.npy" in err and "tofnet simulate" in err
    assert "Traceback" not in err


def test_eval_of_a_csv_needs_the_timing(files, capsys):
    assert main(["eval", str(files / "rec"), str(files / "depth.csv")]) == 2
    assert "--timestep" in capsys.readouterr().err
    assert main(["eval", str(files / "rec"), str(files / "depth.csv"), "--timestep", "1ms",
                 "--latency-steps", "2", "--json", "-"]) == 0
    assert json.loads(capsys.readouterr().out)["mean_abs_m"] == pytest.approx(1.3 / 3)
    # the step as given, not as a float product (7 ms once read 0.006999999999999999)
    assert main(["eval", str(files / "rec"), str(files / "depth.csv"), "--timestep", "7ms",
                 "--latency-steps", "2", "--json", "-"]) == 0
    assert json.loads(capsys.readouterr().out)["timestep_s"] == 0.007


def test_eval_refuses_options_that_contradict_the_file(files, capsys):
    assert main(["eval", str(files / "rec"), str(files / "depth.npz"), "--latency-steps", "1"]) == 2
    assert "latency_steps = 2" in capsys.readouterr().err


def test_eval_and_plot_say_when_the_depth_was_run_on_other_events(files, capsys):
    """A depth file's summary names the events its run read: another count (no window on either side) gets
    one warning line; the scores are still printed."""
    depth = np.empty(3, DEPTH_DTYPE)
    depth["step"], depth["t"], depth["x"], depth["y"], depth["z"] = 2, 13_000, [0, 1, 2], 0, [1.1, 1.8, 4.0]
    write_depth(files / "own.npz", depth, **META, summary={"recording": "rec", "events_in": 4})
    write_depth(files / "other.npz", depth, **META, summary={"recording": "elsewhere", "events_in": 5000})
    write_depth(files / "windowed.npz", depth, **META,
                summary={"recording": "rec", "events_in": 5000, "notes": ["time window 0.1 s .. (...)"]})
    for name, warned in (("own.npz", False), ("other.npz", True), ("windowed.npz", False), ("depth.npz", False)):
        assert main(["eval", str(files / "rec"), str(files / name), "--json", "-"]) == 0, name
        err = capsys.readouterr().err
        assert ("was run on 5,000 events ('elsewhere'), this recording has 4: is it this recording's depth?"
                in err) == warned, (name, err)
    assert main(["plot", "depthmap", str(files / "rec"), str(files / "other.npz"), "--out",
                 str(files / "map.png")]) == 0
    assert "was run on 5,000 events" in capsys.readouterr().err


def test_eval_with_its_own_window_scores_the_part_the_run_read(tmp_path, capsys):
    """A run over 40..60 ms: ``eval --start 0s`` counts that window's events only (the estimates come from them
    alone), and a note says so; a window inside the run's is kept without a note; one outside it is an error."""
    events = make_events([10_000, 10_100, 50_000, 50_100, 50_200, 160_000], [0, 1, 0, 1, 2, 3], [0] * 6, [1] * 6)
    write_ecd(tmp_path / "rec", events, intrinsics=Intrinsics(10, 10, 2, 2), sensor_size=(4, 1),
              gt_depth=np.full(6, 2.0))
    depth = np.empty(2, DEPTH_DTYPE)
    depth["step"], depth["t"] = 42, 10_000 + 43 * 1000  # from the events at 50.0 and 50.1 ms
    depth["x"], depth["y"], depth["z"] = [0, 1], 0, 2.0
    write_depth(tmp_path / "d.npz", depth, summary={"window_us": [40_000, 60_000]}, **META)
    scored = ["eval", str(tmp_path / "rec"), str(tmp_path / "d.npz"), "--json", "-"]
    assert main([*scored, "--start", "0s"]) == 0
    out, err = capsys.readouterr()
    assert (json.loads(out)["events_in"], json.loads(out)["estimates"]) == (3, 2)
    assert err.strip() == (f"tofnet eval: note: scoring 0.03 .. 0.05 s from the first event: the window asked "
                           f"(start 0 s) cut to the run's (0.03 .. 0.05 s from the first event), whose events "
                           f"alone {tmp_path / 'd.npz'}'s estimates come from")
    assert main([*scored, "--start", "40.05ms", "--duration", "5ms"]) == 0  # inside the run's: as asked
    out, err = capsys.readouterr()
    assert (json.loads(out)["events_in"], json.loads(out)["estimates"], err) == (2, 2, "")  # the step overlaps
    assert main([*scored, "--start", "100ms"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"tofnet eval: error: {tmp_path / 'd.npz'}: its run read 0.03 .. 0.05 s from the first event; "
                   "the window asked (start 0.1 s: 0.1 .. the end from the first event) is outside it")
