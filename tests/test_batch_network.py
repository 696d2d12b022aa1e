"""A batch task builds the network `tofnet run RECORDING` builds: the recording's rotation (eq. 7 from
turning poses) and its lens (A t through the distortion) decide the default network in both."""

import json

import numpy as np
import pytest

from tofnet.batch import expand, load_plan
from tofnet.batch.worker import run_task
from tofnet.cli import main
from tofnet.io import read_depth
from tofnet.io.ecd import write_ecd
from tofnet.io.recording import Intrinsics
from tofnet.testing import camera_flow, flowing_pattern, turning_trajectory

SIZE = (40, 24)
PINHOLE = Intrinsics(200.0, 200.0, 19.5, 11.5)
LENS = Intrinsics(200.0, 200.0, 19.5, 11.5, (-0.05, 0.01, 0.0, 0.0, 0.0))  # a mild radtan lens
VELOCITY = (-0.45, 0.0, 0.0)
OMEGA = (0.0, -0.25, 0.0)  # turning left: eq. 8 would read the turn as depth
DURATION_US = 300_000


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A camera translating and turning, with its poses and a distorted lens in calib.txt, as an ECD folder."""
    folder = tmp_path_factory.mktemp("batch-network")
    events = flowing_pattern(SIZE, camera_flow(PINHOLE, 1.5, VELOCITY, OMEGA), DURATION_US, seed=21)
    trajectory = turning_trajectory(VELOCITY, OMEGA, DURATION_US * 1e-6 + 0.05)
    write_ecd(folder / "turning", events, intrinsics=LENS, sensor_size=SIZE, gt_depth=np.full(len(events), 1.5),
              times=trajectory.times, positions=trajectory.positions, quaternions=trajectory.quaternions)
    return folder


def test_a_task_on_a_turning_recording_through_a_lens_equals_tofnet_run(folder):
    (folder / "plan.yaml").write_text("name: t\noutput: out\nrecordings: [turning]\n"
                                      "grid:\n  refractory: [0]\nkeep: [summary, depth]\n")
    row = run_task(expand(load_plan(folder / "plan.yaml"))[0])
    assert row["status"] == "ok", row["error"]
    out, summary_file = folder / "alone.npz", folder / "alone.json"
    assert main(["run", str(folder / "turning"), "--refractory", "0", "--out", str(out), "--json",
                 str(summary_file), "--quiet", "--force"]) == 0
    alone = json.loads(summary_file.read_text())
    assert alone["rotation"] == "eq. 7, ω from the ground-truth poses -> depth"  # what the batch must build too
    assert alone["undistortion"]["velocity"] == "velocity"
    assert (row["events_in"], row["accepted"], row["tot_spikes"], row["depth_out"]) == \
        (alone["events_in"], alone["accepted"], alone["tot_spikes"], alone["depth_out"])
    assert {r: row[f"rejected_{r}"] for r in alone["rejected"]} == alone["rejected"]
    batch_depth, _ = read_depth(row["depth_file"])
    alone_depth, _ = read_depth(out)
    assert len(alone_depth) > 200 and batch_depth.tobytes() == alone_depth.tobytes()
    assert np.median(batch_depth["z"]) == pytest.approx(1.5, rel=0.05)  # the turn compensated, not read as depth
    summary = json.loads(open(row["summary_file"]).read())
    assert summary["counts"] == alone["counts"]


def test_a_networks_estimator_is_tofnet_runs_estimator(folder):
    (folder / "plan.yaml").write_text("name: t\noutput: out\nrecordings: [turning]\n"
                                      "networks: [paper, {estimator: improved}]\nkeep: [summary, depth]\n")
    paper, improved = expand(load_plan(folder / "plan.yaml"))
    assert (paper.network.name, improved.network.name) == ("paper", "improved")
    assert improved.task_id.startswith("turning.improved-") and improved.task_id != paper.task_id
    row = run_task(improved)
    assert row["status"] == "ok", row["error"]
    out, summary_file = folder / "improved.npz", folder / "improved.json"
    assert main(["run", str(folder / "turning"), "--estimator", "improved", "--out", str(out), "--json",
                 str(summary_file), "--quiet", "--force"]) == 0
    alone = json.loads(summary_file.read_text())
    assert "time_surface" in alone["counts"] and (row["events_in"], row["depth_out"]) == \
        (alone["events_in"], alone["depth_out"])
    batch_depth, _ = read_depth(row["depth_file"])
    alone_depth, _ = read_depth(out)
    assert len(alone_depth) > 100 and batch_depth.tobytes() == alone_depth.tobytes()
    assert json.loads(open(row["summary_file"]).read())["counts"] == alone["counts"]


def test_rotation_and_undistort_false_are_tofnet_runs_no_rotation_and_no_undistort(folder):
    (folder / "plan.yaml").write_text("name: t\noutput: out\nrecordings: [turning]\nnetworks:\n  - paper\n"
                                      "  - {spec: paper, name: plain, rotation: false, undistort: false}\n"
                                      "grid:\n  refractory: [0]\nkeep: [summary, depth]\n")
    paper, plain = expand(load_plan(folder / "plan.yaml"))
    assert plain.task_id != paper.task_id
    row = run_task(plain)
    assert row["status"] == "ok", row["error"]
    out, summary_file = folder / "plain.npz", folder / "plain.json"
    assert main(["run", str(folder / "turning"), "--refractory", "0", "--no-rotation", "--no-undistort", "--out",
                 str(out), "--json", str(summary_file), "--quiet", "--force"]) == 0
    alone = json.loads(summary_file.read_text())
    summary = json.loads(open(row["summary_file"]).read())
    assert "--no-rotation" in alone["rotation"] and summary["rotation"] == alone["rotation"]
    assert summary["undistortion"] == alone["undistortion"] and "--no-undistort" in json.dumps(alone["undistortion"])
    batch_depth, _ = read_depth(row["depth_file"])
    alone_depth, _ = read_depth(out)
    assert len(alone_depth) > 200 and batch_depth.tobytes() == alone_depth.tobytes()
    with_turn, _ = read_depth(run_task(paper)["depth_file"])
    assert with_turn.tobytes() != batch_depth.tobytes()  # the switches changed the network


@pytest.fixture(scope="module")
def distorted(tmp_path_factory):
    """A simulated slider through the DAVIS240C's lens (an ECD folder), and a spec that undistorts its spikes."""
    from tofnet.io.spec import dump_spec
    from tofnet.networks import depth_network
    from tofnet.sim import generate, scenario
    from tofnet.sim.run import write_result
    size = (60, 45)
    config = scenario("slider", 0.25).replace(sensor_size=size)
    k = config.intrinsics
    config = config.replace(intrinsics=Intrinsics(k.fx, k.fy, k.cx, k.cy, (-0.368, 0.150, -0.0003, -0.0008, 0.0)))
    folder = tmp_path_factory.mktemp("batch-lens")
    write_result(generate(config, seed=0), folder / "slider")
    (folder / "moved.yaml").write_text(dump_spec(depth_network(size, undistort={})))
    return folder


def test_a_task_with_an_undistort_spec_says_so_and_is_scored_at_the_undistorted_pixels(distorted, capsys):
    (distorted / "plan.yaml").write_text("name: t\noutput: out\nrecordings: [slider]\nnetworks: [moved.yaml]\n"
                                         "keep: [summary, metrics, depth]\n")
    row = run_task(expand(load_plan(distorted / "plan.yaml"))[0])
    assert row["status"] == "ok", row["error"]
    out, summary_file = distorted / "alone.npz", distorted / "alone.json"
    assert main(["run", str(distorted / "slider"), "--spec", str(distorted / "moved.yaml"), "--out", str(out),
                 "--json", str(summary_file), "--quiet", "--force"]) == 0
    alone = json.loads(summary_file.read_text())
    summary = json.loads(open(row["summary_file"]).read())
    assert alone["undistortion"]["counts"]["passed"] > 1000
    assert (summary["undistortion"], summary["rotation"]) == (alone["undistortion"], alone["rotation"])
    batch_depth, batch_meta = read_depth(row["depth_file"])
    alone_depth, alone_meta = read_depth(out)
    assert batch_depth.tobytes() == alone_depth.tobytes()
    # `tofnet eval` and `export` read the lens from the depth file: the batch's file records it as tofnet run's does
    assert batch_meta["summary"]["undistortion"] == alone_meta["summary"]["undistortion"] is not None
    capsys.readouterr()
    assert main(["eval", str(distorted / "slider"), str(out), "--json", "-"]) == 0
    scored = json.loads(capsys.readouterr().out)
    assert scored["matched"] == len(alone_depth) > 500 and scored["unmatched"] == 0
    assert (row["matched"], row["median_abs_m"]) == (scored["matched"], pytest.approx(scored["median_abs_m"]))


def test_a_task_on_a_time_window_records_it_as_run_does(folder, capsys):
    """The depth file of a windowed task holds its window (window_us): eval reads the same events as for run's."""
    (folder / "plan_w.yaml").write_text("name: w\noutput: out_w\nrecordings: [turning]\nstart: 100ms\n"
                                        "duration: 100ms\ngrid:\n  refractory: [0]\nkeep: [summary, depth]\n")
    row = run_task(expand(load_plan(folder / "plan_w.yaml"))[0])
    assert row["status"] == "ok", row["error"]
    assert main(["run", str(folder / "turning"), "--refractory", "0", "--start", "100ms", "--duration", "100ms",
                 "--out", str(folder / "alone_w.npz"), "--quiet", "--force"]) == 0
    batch_meta, alone_meta = read_depth(row["depth_file"])[1], read_depth(folder / "alone_w.npz")[1]
    assert batch_meta["summary"]["window_us"] == alone_meta["summary"]["window_us"]
    start, stop = batch_meta["summary"]["window_us"]
    assert stop - start == 100_000
    capsys.readouterr()
    (folder / "bad.npz").write_bytes((folder / "alone_w.npz").read_bytes())
    from tofnet.io.depth import write_depth
    depth, meta = read_depth(folder / "alone_w.npz")
    write_depth(folder / "bad.npz", depth, t0_us=meta["t0_us"], timestep_us=meta["timestep_us"],
                latency_steps=meta["latency_steps"], summary={**meta["summary"], "window_us": [stop, start]})
    assert main(["eval", str(folder / "turning"), str(folder / "bad.npz")]) == 2  # a stranger's window: one line
    assert "bad.npz: its summary's window_us is not [start, stop] in µs" in capsys.readouterr().err
