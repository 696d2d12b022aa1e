"""Eq. 7 through the process graph: the angular velocity process, the depth neurons on every backend,
the default network and `tofnet run` on recordings with turning poses or a gyroscope."""

from __future__ import annotations

import numpy as np
import pytest

from tofnet.api import default_network, run
from tofnet.cli import main
from tofnet.compiler import compile_network
from tofnet.compiler.report import format_report
from tofnet.core.network import Network
from tofnet.errors import DataError, NetworkError
from tofnet.io import read_depth, read_recording
from tofnet.io.ecd import write_ecd
from tofnet.io.recording import Intrinsics, Recording
from tofnet.io.rotation import write_imu
from tofnet.models.angular_velocity import AngularVelocityModel
from tofnet.models.base import ModelContext
from tofnet.networks import depth_network
from tofnet.processes import AngularVelocityProcess, DepthProcess
from tofnet.testing import camera_flow, flowing_pattern, turning_trajectory

from optional import optional

SIZE = (40, 24)
K = Intrinsics(200.0, 200.0, 19.5, 11.5)
DEPTH_M = 1.5
VELOCITY = (-0.45, 0.0, 0.0)  # 60 px/s of image motion at 1.5 m
OMEGA = (0.0, -0.25, 0.0)  # turning left: about 50 px/s more, the same way
DURATION_US = 400_000


def share() -> float:
    """The true translational share of the image motion at the centre: 60 / (60 + 50)."""
    translation = -K.fx * VELOCITY[0] / DEPTH_M
    return translation / (translation - K.fx * OMEGA[1])


@pytest.fixture(scope="module")
def events():
    return flowing_pattern(SIZE, camera_flow(K, DEPTH_M, VELOCITY, OMEGA), DURATION_US, seed=21)


def turning(events, rotation=True, omega=OMEGA, **depth) -> tuple[Network, Recording]:
    net = depth_network(SIZE, input={"refractory": 0, "t0": 0}, depth=depth,
                        velocity={"source": "constant", "velocity": list(VELOCITY), "per": "pixel"},
                        rotation={"source": "constant", "omega": list(omega)} if rotation else None)
    return net, Recording(events, intrinsics=K, sensor_size=SIZE)


@pytest.mark.parametrize("backend", ["reference", "float", "fixed"])
def test_compensated_depth_is_right_and_uncompensated_is_wrong(events, backend):
    compensated, _ = run(*reversed(turning(events)), backend=backend)
    plain, _ = run(*reversed(turning(events, rotation=False)), backend=backend)
    assert len(compensated.depth) > 500 and len(plain.depth) > 500
    assert np.median(compensated.depth["z"]) == pytest.approx(DEPTH_M, rel=0.05)
    # eq. 8 reads the turn as depth: Z r
    assert np.median(plain.depth["z"]) == pytest.approx(DEPTH_M * share(), rel=0.08)
    assert plain.rejected["rotation_dominated"] == 0  # eq. 8 never tests the share


def test_multiproc_equals_fixed_bit_for_bit_with_rotation(events):
    net, recording = turning(events)
    compiled = compile_network(net, patch=(16, 10))  # 3x3 cores per layer, seams in both directions
    fixed, _ = run(recording, net, backend="fixed", compile_options={"patch": (16, 10)}, record_tot=True)
    multi, _ = run(recording, net, backend="multiproc", backend_options={"workers": 2},
                   compile_options={"patch": (16, 10)}, record_tot=True)
    assert compiled.layers[1].cores == 9
    assert len(fixed.depth) > 500 and fixed.depth.tobytes() == multi.depth.tobytes()
    assert fixed.counts == multi.counts


@pytest.mark.parametrize("backend", ["float", "fixed"])
def test_zero_rotation_is_eq_8_bit_for_bit(events, backend):
    plain, _ = run(*reversed(turning(events, rotation=False)), backend=backend)  # the fused paper chain
    still, _ = run(*reversed(turning(events, omega=(0.0, 0.0, 0.0))), backend=backend)  # eq. 7, model by model
    assert len(plain.depth) > 500 and plain.depth.tobytes() == still.depth.tobytes()
    assert plain.counts["depth"] == still.counts["depth"]


def test_the_share_threshold_rejects_and_counts():
    net_low, rec = turning(flowing_pattern(SIZE, camera_flow(K, DEPTH_M, VELOCITY, OMEGA), 200_000, seed=3),
                           min_share=0.0)
    net_high, _ = turning(rec.events, min_share=0.6)
    low, _ = run(rec, net_low, backend="fixed")
    high, _ = run(rec, net_high, backend="fixed")
    moved = high.rejected["rotation_dominated"] - low.rejected["rotation_dominated"]
    assert moved > 100 and len(low.depth) - len(high.depth) == moved - (
        high.rejected["too_near"] - low.rejected["too_near"]) - (high.rejected["too_far"] - low.rejected["too_far"])
    assert sum(high.counts["depth"].values()) == sum(low.counts["depth"].values())  # every neuron counted once


def test_the_compiler_notes_the_division_and_the_accumulators():
    net = depth_network(SIZE, rotation={"source": "constant", "omega": [0, 0.1, 0]})
    report = format_report(compile_network(net))
    assert "depth: eq. 7" in report and "division" in report
    assert net.process("depth").resources_per_pixel["accumulators"] == 8
    assert "notes" not in format_report(compile_network(depth_network(SIZE)))
    assert DepthProcess().resources_per_pixel["accumulators"] == 6


# -- the angular velocity process and its model -----------------------------------------------------


def test_updates_are_sent_every_update_every_steps_sampled_at_the_start_of_their_step(tmp_path):
    samples = tmp_path / "w.txt"
    samples.write_text("0.0 0 0 0\n1.0 1 -2 3\n")  # rad/s, linear in time
    process = AngularVelocityProcess(source="samples", samples=str(samples), update_every=4)
    ctx = ModelContext("fixed", SIZE, 250_000, 1000, recording=Recording(np.empty(0, events_dtype()), intrinsics=K))
    sent = AngularVelocityModel(process, ctx).run(0, 10, {})["b_w"]
    assert sent["step"].tolist() == [0, 4, 8]
    np.testing.assert_allclose(sent["wx"], [0.25, 0.254, 0.258])  # t0 + j * 4 ms
    np.testing.assert_allclose(sent["wz"], 3 * sent["wx"])
    assert AngularVelocityModel.output_meta(process, ctx)["b_w"].intrinsics == (K.fx, K.fy, K.cx, K.cy)


def events_dtype():
    from tofnet.events import EVENT_DTYPE
    return EVENT_DTYPE


def test_the_gyroscope_is_rotated_shifted_and_unbiased():
    t = np.linspace(0.0, 1.0, 1001)
    gyro = np.column_stack([0.1 + 0 * t, 0.2 * t, -0.3 + 0 * t])  # rad/s in the IMU frame
    imu = np.column_stack([t, np.zeros((len(t), 3)), gyro])
    recording = Recording(np.empty(0, events_dtype()), intrinsics=K, imu=imu)
    # 90° about z (quaternion): IMU x -> camera y, IMU y -> camera -x
    process = AngularVelocityProcess(source="gyro", rotation_cam_imu=[0, 0, np.sqrt(0.5), np.sqrt(0.5)],
                                     time_shift="10ms", bias=[0.01, 0.0, 0.0])
    sent = AngularVelocityModel(process, ModelContext("float", SIZE, 0, 1000, recording=recording)).run(0, 501, {})
    row = sent["b_w"][500]  # step 500: t = 0.5 s, read at 0.51 s
    np.testing.assert_allclose([row["wx"], row["wy"], row["wz"]], [-0.2 * 0.51, 0.1 - 0.01, -0.3], atol=1e-12)


def test_sources_say_what_they_miss():
    with pytest.raises(NetworkError, match="needs omega"):
        AngularVelocityProcess(source="constant")
    with pytest.raises(NetworkError, match="apply to source: gyro only"):
        AngularVelocityProcess(source="groundtruth", time_shift="5ms")
    with pytest.raises(NetworkError, match="rotation matrix"):
        AngularVelocityProcess(source="gyro", rotation_cam_imu=[1, 0, 0, 0, 2, 0, 0, 0, 1])
    with pytest.raises(NetworkError, match="unit length"):
        AngularVelocityProcess(source="gyro", rotation_cam_imu=[0, 0, 0, 2])
    with pytest.raises(NetworkError, match="min_share"):
        DepthProcess(min_share=1.0)
    bare = Recording(np.empty(0, events_dtype()), intrinsics=K)
    for source, what in (("gyro", "no IMU samples"), ("groundtruth", "no ground-truth poses")):
        with pytest.raises(DataError, match=what):
            AngularVelocityModel(AngularVelocityProcess(source=source), ModelContext("fixed", SIZE, 0, 1000,
                                                                                     recording=bare))


# -- the default network and `tofnet run` ---------------------------------------------------------


def write_recording(folder, events, *, poses: bool, imu: bool) -> None:
    trajectory = turning_trajectory(VELOCITY, OMEGA, DURATION_US * 1e-6 + 0.05)
    times = trajectory.times
    write_ecd(folder, events, intrinsics=K, sensor_size=SIZE, gt_depth=np.full(len(events), DEPTH_M),
              **({"times": times, "positions": trajectory.positions, "quaternions": trajectory.quaternions}
                 if poses else {}))
    if imu:
        t = np.arange(0.0, 0.5, 0.005)
        write_imu(folder / "imu.txt", t, np.zeros((len(t), 3)), np.tile(OMEGA, (len(t), 1)))


@pytest.mark.parametrize("kind", ["poses", "gyro", "aedat4"])
def test_tofnet_run_compensates_rotation_from_poses_or_a_gyro_and_says_so(events, tmp_path, capsys, kind):
    """``aedat4``: the gyroscope of an AEDAT4 file, whose IMU comes among its packets (a stream of its events
    built the network without it: no rotation, and nothing said)."""
    folder = tmp_path / kind
    write_recording(folder, events, poses=kind == "poses", imu=kind != "poses")
    if kind == "aedat4":
        optional("faery")
        assert main(["convert", str(folder), str(tmp_path / "rec.aedat4"), "--quiet"]) == 0
        folder = tmp_path / "rec.aedat4"
    velocity = [] if kind == "poses" else ["--velocity=" + ",".join(map(str, VELOCITY))]  # no poses: a constant A t
    out = tmp_path / "depth.npz"
    assert main(["run", str(folder), "--out", str(out), "--refractory", "0", "--velocity-per", "pixel", "--quiet",
                 *velocity]) == 0
    printed = capsys.readouterr().out
    assert ("ω from the ground-truth poses" if kind == "poses" else "ω from the gyroscope (the recording's IMU; its axes taken as the camera's, rad/s") in printed
    assert "rotation dominated" in printed
    depth, meta = read_depth(out)
    assert np.median(depth["z"]) == pytest.approx(DEPTH_M, rel=0.05)
    assert main(["run", str(folder), "--out", str(out), "--refractory", "0", "--velocity-per", "pixel", "--quiet",
                 "--no-rotation", "--force", *velocity]) == 0
    assert "not compensated (eq. 8: --no-rotation)" in capsys.readouterr().out
    depth, _ = read_depth(out)
    assert np.median(depth["z"]) == pytest.approx(DEPTH_M * share(), rel=0.08)


def test_the_default_network_compensates_only_recordings_that_turn(tmp_path, events):
    write_recording(tmp_path / "turning", events, poses=True, imu=False)
    recording = read_recording(tmp_path / "turning")
    assert default_network(recording).process("angular_velocity").source == "groundtruth"
    assert len(default_network(recording, rotation=False).processes) == 4
    still = Recording(events, intrinsics=K, trajectory=turning_trajectory(VELOCITY, (0, 0, 0), 0.5))
    assert len(default_network(still).processes) == 4  # poses that never turn: eq. 8, the fused paper chain


def test_a_spec_with_rotation_runs_and_no_rotation_refuses_it(tmp_path, events, capsys):
    write_recording(tmp_path / "rec", events, poses=True, imu=True)
    spec = tmp_path / "rotation.yaml"
    text = (__import__("pathlib").Path(__file__).parent.parent / "examples" / "rotation.yaml").read_text()
    spec.write_text(text.replace("[240, 180]", f"[{SIZE[0]}, {SIZE[1]}]").replace("refractory: 60ms", "refractory: 0"))
    out = tmp_path / "depth.npz"
    assert main(["run", str(tmp_path / "rec"), "--spec", str(spec), "--out", str(out), "--quiet"]) == 0
    assert "ω from the gyroscope (the recording's IMU with its camera-IMU rotation)" in capsys.readouterr().out
    assert main(["run", str(tmp_path / "rec"), "--spec", "examples/paper_240x180.yaml", "--sensor-size", "40x24",
                 "--out", str(out), "--quiet", "--force"]) == 0
    assert "not compensated (eq. 8: the spec has no angular velocity process)" in capsys.readouterr().out
    assert main(["run", str(tmp_path / "rec"), "--spec", str(spec), "--out", str(out), "--quiet",
                 "--no-rotation", "--force"]) == 2
    assert "remove it from the spec" in capsys.readouterr().err


def test_tofnet_eval_splits_the_error_by_the_true_share(events, tmp_path, capsys):
    import json
    for kind in ("poses", "gyro"):
        write_recording(tmp_path / kind, events, poses=kind == "poses", imu=kind == "gyro")
    out = tmp_path / "depth.npz"
    assert main(["run", str(tmp_path / "poses"), "--out", str(out), "--refractory", "0", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["eval", str(tmp_path / "poses"), str(out), "--window", "0", "--json", str(tmp_path / "e.json")]) == 0
    printed = capsys.readouterr().out
    assert "error by translational share r (true share along the true image motion" in printed
    split = json.loads((tmp_path / "e.json").read_text())["share_split"]
    filled = [row for row in split if row["n"]]
    # every estimate sees the same motion: one bin, at the scene's share (x²/f adds up to 1 % to B ω)
    assert len(filled) == 1 and filled[0]["share"] == pytest.approx(share(), rel=0.02)
    assert filled[0]["lo"] <= share() < filled[0]["hi"]
    assert main(["eval", str(tmp_path / "gyro"), str(out), "--window", "0"]) == 0
    assert "not available (needs ground-truth poses" in capsys.readouterr().out
