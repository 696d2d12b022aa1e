"""The simulator with a turning camera: trajectory maths, renders, ground truth, IMU and scenarios."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tofnet.io.ecd import read_ecd
from tofnet.io.groundtruth import quaternion_to_matrix
from tofnet.io.recording import Intrinsics
from tofnet.io.rotation import PoseAngularVelocity, read_gyroscope
from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.velocity import velocity_term
from tofnet.sim import (ROTATION_SCENARIOS, ImuModel, Plane, RotatingTrajectory, Scene, SimConfig, SimError, Sway,
                        Texture, constant, generate, scenario, simulate)

K = Intrinsics(fx=100.0, fy=100.0, cx=31.5, cy=7.5)
SIZE = (64, 16)


def wobbly(velocity=(0.3, -0.1, 0.2)) -> RotatingTrajectory:
    return RotatingTrajectory(constant(velocity, 1.0),
                              yaw=Sway(offset=0.1, rate=0.2, waves=((0.05, 2.0, 0.3),)),
                              pitch=Sway(waves=((0.08, 1.5, 1.0), (0.02, 5.0, 0.0))),
                              roll=Sway(offset=-0.2, rate=-0.4))


def test_angular_velocity_is_the_derivative_of_the_orientation():
    trajectory = wobbly()
    h = 1e-6
    for t in (0.0, 0.137, 0.5, 0.93):
        r = trajectory.rotation_at(t)[0]
        dr = (trajectory.rotation_at(t + h)[0] - trajectory.rotation_at(t - h)[0]) / (2 * h)
        skew = r.T @ dr
        np.testing.assert_allclose(trajectory.angular_velocity_at(t)[0], [skew[2, 1], skew[0, 2], skew[1, 0]],
                                   atol=1e-7)
        np.testing.assert_allclose(quaternion_to_matrix(trajectory.quaternion_at(t))[0], r, atol=1e-14)
        np.testing.assert_allclose(trajectory.velocity_at(t)[0], r.T @ np.array([0.3, -0.1, 0.2]), atol=1e-14)
    assert np.linalg.norm(trajectory.angular_velocity_at(np.linspace(0, 1, 500)), axis=1).max() \
        <= trajectory.max_angular_speed


def test_positive_yaw_turns_the_camera_right():
    trajectory = RotatingTrajectory(constant((0.0, 0.0, 0.0), 1.0), yaw=Sway(rate=0.5))
    optical_axis = trajectory.rotation_at(0.5)[0] @ np.array([0.0, 0.0, 1.0])
    assert optical_axis[0] > 0  # towards world +x, the right
    np.testing.assert_allclose(trajectory.angular_velocity_at(0.5), [[0.0, 0.5, 0.0]])


def edge_config(trajectory, z=1.0) -> SimConfig:
    plane = Plane(center=(0.0, 0.0, z), size=(4.0, 2.0), texture=Texture("edge", levels=(0.2, 0.8), angle=0.0))
    return SimConfig("edge", Scene((plane,), background_depth=z + 2.0), trajectory, 0.6, intrinsics=K,
                     sensor_size=SIZE, contrast_sigma=0.0)


def first_event_times(events, width):
    out = np.full(width, np.nan)
    for u in range(width):
        sel = events[events["x"] == u]
        if sel.size:
            out[u] = np.median([sel["t"][sel["y"] == y].min() for y in np.unique(sel["y"])]) * 1e-6
    return out


@pytest.mark.parametrize("slide", [0.0, 0.25])
def test_an_edge_crosses_the_columns_when_the_projection_says(slide):
    """A vertical edge at world x = 0, z = 1 while the camera yaws (and slides): column times follow the projection."""
    trajectory = RotatingTrajectory(constant((slide, 0.0, 0.0), 0.6, start=(0.0, 0.0, 0.0)),
                                    yaw=Sway(offset=-0.25, rate=0.7))
    result = generate(edge_config(trajectory), seed=2)
    assert result.stats["max_render_step_px"] <= 0.25
    fine = np.linspace(0.0, 0.6, 60001)
    camera = np.einsum("nji,nj->ni", trajectory.rotation_at(fine),
                       np.array([0.0, 0.0, 1.0]) - trajectory.position_at(fine))
    u_of_t = K.cx + K.fx * camera[:, 0] / camera[:, 2]  # decreasing: the edge moves left
    times = first_event_times(result.events, SIZE[0])
    cols = np.arange(SIZE[0])
    crossed = (cols > u_of_t.min() + 2) & (cols < u_of_t.max() - 2) & np.isfinite(times)
    assert crossed.sum() >= 20
    predicted = np.interp(cols[crossed], u_of_t[::-1], fine[::-1])
    slope, _ = np.polyfit(predicted, times[crossed], 1)
    assert slope == pytest.approx(1.0, abs=0.02)
    # The ground truth is the depth of the plane along each pixel's ray, in the camera frame.
    ev, gt = result.events, result.gt_depth
    t = ev["t"] * 1e-6
    rays = np.column_stack([(ev["x"] - K.cx) / K.fx, (ev["y"] - K.cy) / K.fy, np.ones(len(ev))])
    world = np.einsum("nij,nj->ni", trajectory.rotation_at(t), rays)
    np.testing.assert_allclose(gt, (1.0 - trajectory.position_at(t)[:, 2]) / world[:, 2], rtol=1e-3)


def test_imu_reads_the_true_rotation_and_poses_agree(tmp_path):
    config = edge_config(wobbly((0.2, 0.0, 0.0))).replace(duration=0.2, imu=ImuModel(rate=500.0))
    summary = simulate(config, tmp_path / "w", seed=1)
    assert "imu.txt" in summary["files"] and summary["max_angular_speed_radps"] > 0
    recording = read_ecd(tmp_path / "w")
    t = np.linspace(0.01, 0.19, 37)
    truth = config.trajectory.angular_velocity_at(t)
    gyro = read_gyroscope(tmp_path / "w" / "imu.txt")
    np.testing.assert_allclose(gyro.angular_velocity_at(np.arange(0, 0.2, 0.002)),
                               config.trajectory.angular_velocity_at(np.arange(0, 0.2, 0.002)), atol=1e-12)
    np.testing.assert_allclose(gyro.angular_velocity_at(t), truth, atol=5e-3)  # linear between 2 ms samples
    # Poses every 1 ms: the slerp turns at the segment's mean rate.
    segment = np.floor(t * 1000) / 1000
    mean_rate = np.mean([config.trajectory.angular_velocity_at(segment + f * 1e-3) for f in np.linspace(0, 1, 101)],
                        axis=0)
    np.testing.assert_allclose(PoseAngularVelocity(recording.trajectory).angular_velocity_at(t), mean_rate, atol=1e-4)
    np.testing.assert_allclose(recording.trajectory.velocity_at(t), config.trajectory.velocity_at(t), atol=1e-4)
    # Accelerometer: gravity (world +y, down) in the camera frame, 9.81 m/s^2 pointing up.
    up = np.einsum("nji,j->ni", config.trajectory.rotation_at(recording.imu[:, 0]), [0.0, -9.81, 0.0])
    np.testing.assert_allclose(recording.imu[:, 1:4], up, atol=1e-12)
    assert np.all(recording.imu[:, 2] < -9.0)


def test_gyro_noise_and_bias_have_the_documented_size():
    imu = ImuModel(rate=1000.0, gyro_noise_density=0.002, gyro_bias=(0.01, -0.02, 0.0))
    trajectory = RotatingTrajectory(constant((0.0, 0.0, 0.0), 4.0), yaw=Sway(rate=0.3))
    rows = imu.sample(trajectory, 4.0, np.random.default_rng(0))
    error = rows[:, 4:7] - trajectory.angular_velocity_at(rows[:, 0])
    np.testing.assert_allclose(error.mean(axis=0), imu.gyro_bias, atol=0.002)
    np.testing.assert_allclose(error.std(axis=0), 0.002 * math.sqrt(1000.0), rtol=0.1)
    with pytest.raises(SimError, match="gyro_noise_density"):
        ImuModel(gyro_noise_density=-1.0)


def test_translational_scenarios_have_no_imu_and_identity_poses():
    result = generate(scenario("slider", 0.01).replace(sensor_size=(32, 24)), seed=0)
    assert result.imu is None
    np.testing.assert_array_equal(result.quaternions, np.tile([0.0, 0.0, 0.0, 1.0], (len(result.quaternions), 1)))


def translational_share(result) -> np.ndarray:
    """Per event: the share of the image motion ``F = A t / Z + B ω`` along ``F`` due to translation."""
    config, k = result.config, result.config.intrinsics
    ev = result.events
    t = ev["t"] * 1e-6
    v, w = config.trajectory.velocity_at(t), config.trajectory.angular_velocity_at(t)
    u, y = ev["x"].astype(float), ev["y"].astype(float)
    at = np.array([velocity_term(*v[i], u[i], y[i], k.fx, k.fy, k.cx, k.cy) for i in range(len(ev))])
    bw = np.array([rotational_flow(*w[i], u[i], y[i], k.fx, k.fy, k.cx, k.cy) for i in range(len(ev))])
    translation = at / result.gt_depth[:, None]
    flow = translation + bw
    return np.sum(translation * flow, axis=1) / np.sum(flow * flow, axis=1)


@pytest.mark.parametrize("name", list(ROTATION_SCENARIOS))
def test_rotation_scenarios(name, tmp_path):
    summary = simulate(name, tmp_path / name, duration=0.03, seed=1, sensor_size=(48, 36))
    assert summary["events"] > 0 and summary["max_render_step_px"] <= 0.25
    assert "imu.txt" in summary["files"]
    recording = read_ecd(tmp_path / name)
    assert 0.2 < recording.gt_depth.min() and recording.gt_depth.max() < 3.5
    assert PoseAngularVelocity(recording.trajectory).rotates
    result = generate(scenario(name, 0.2).replace(sensor_size=(48, 36)), seed=0)
    share = np.median(translational_share(result))
    if name == "pan":
        assert share < 0.4  # rotation dominates
    else:
        assert share > 0.8  # translation dominates
