"""Angular velocity sources (tofnet/io/rotation.py): poses, gyroscope, samples, constant."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.io.ecd import read_ecd, write_ecd
from tofnet.io.groundtruth import Trajectory, quaternion_to_matrix
from tofnet.io.recording import Intrinsics, Recording
from tofnet.io.rotation import (AngularVelocitySamples, ConstantAngularVelocity, Gyroscope, PoseAngularVelocity,
                                angular_velocity_of, quaternion_multiply, read_angular_velocity_samples,
                                read_gyroscope, relative_rotation_vector, write_angular_velocity_samples, write_imu)
from tofnet.testing import make_events


def axis_angle_quaternion(vectors: np.ndarray) -> np.ndarray:
    """Unit quaternions (``qx qy qz qw``) of rotation vectors (rows, rad)."""
    vectors = np.atleast_2d(vectors)
    angle = np.linalg.norm(vectors, axis=1)
    axis = np.divide(vectors, angle[:, None], out=np.zeros_like(vectors), where=angle[:, None] > 0)
    return np.column_stack([axis * np.sin(angle / 2)[:, None], np.cos(angle / 2)])


def constant_rotation_poses(omega, times, start=(0.2, -0.4, 0.1)):
    """Poses of a camera turning at ``omega`` (rad/s, camera frame) from orientation ``start``."""
    q0 = axis_angle_quaternion(np.array(start))
    q = quaternion_multiply(np.repeat(q0, len(times), axis=0), axis_angle_quaternion(np.outer(times, omega)))
    return q


def test_quaternion_product_composes_rotations():
    a, b = axis_angle_quaternion(np.array([[0.3, -0.2, 0.9], [-1.1, 0.4, 0.2]]))
    product = quaternion_multiply(a[None], b[None])
    np.testing.assert_allclose(quaternion_to_matrix(product)[0],
                               quaternion_to_matrix(a[None])[0] @ quaternion_to_matrix(b[None])[0], atol=1e-15)


@pytest.mark.parametrize("omega", [(0.0, 0.8, 0.0), (0.3, -0.5, 1.2), (2e-7, 0.0, -1e-7), (0.0, 0.0, 0.0)])
def test_constant_rotation_is_recovered_from_poses(omega):
    times = np.linspace(0.0, 1.0, 201)
    q = constant_rotation_poses(omega, times)
    q[::3] *= -1  # q and -q are one orientation
    trajectory = Trajectory(times, np.outer(times, [0.5, 0.0, 0.0]), q)
    source = PoseAngularVelocity(trajectory)
    t = np.array([-0.5, 0.0, 0.0123, 0.5, 0.99999, 1.0, 3.0])
    np.testing.assert_allclose(source.angular_velocity_at(t), np.tile(omega, (len(t), 1)), atol=1e-12)
    assert source.rotates == (np.linalg.norm(omega) > 1e-6)  # turned more than STILL_ANGLE in 1 s


def test_pose_rate_is_the_derivative_of_the_slerp():
    times = np.array([0.0, 0.01, 0.03, 0.06])
    q = axis_angle_quaternion(np.array([[0, 0, 0], [0.02, 0.01, 0.0], [0.05, -0.03, 0.02], [0.06, -0.02, 0.09]]))
    trajectory = Trajectory(times, np.zeros((4, 3)), q)
    source = PoseAngularVelocity(trajectory)
    h = 1e-6
    for t in (0.004, 0.02, 0.045):
        _, r0 = trajectory.pose_at(np.array([t - h]))
        _, r1 = trajectory.pose_at(np.array([t + h]))
        _, r = trajectory.pose_at(np.array([t]))
        skew = r[0].T @ (r1[0] - r0[0]) / (2 * h)  # [ω]x = R^T dR/dt
        numeric = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        np.testing.assert_allclose(source.angular_velocity_at(t)[0], numeric, atol=1e-6)


def test_relative_rotation_is_accurate_for_tiny_and_large_angles():
    vectors = (np.array([1e-12, 0, 0]), np.array([0, 3e-9, 0]), np.array([0.0, 0.0, 3.1]), np.array([1.0, 2.0, -1.5]))
    for vector in vectors:
        vector = vector if np.linalg.norm(vector) < math.pi else vector / np.linalg.norm(vector) * 3.0
        q0 = axis_angle_quaternion(np.array([0.4, 0.1, -0.3]))
        q1 = quaternion_multiply(q0, axis_angle_quaternion(vector))
        # Absolute accuracy ~1e-16 rad: what the float64 quaternions themselves hold.
        np.testing.assert_allclose(relative_rotation_vector(q0, q1)[0], vector, rtol=1e-9, atol=1e-15)


def omega_cam(t):
    """A camera-frame angular velocity linear in time (so interpolation is exact)."""
    t = np.atleast_1d(t)
    return np.column_stack([0.1 + 2.0 * t, -0.3 + 0.5 * t, 0.05 - 1.0 * t])


def test_gyroscope_with_rotation_and_time_shift(tmp_path):
    r_cam_imu = quaternion_to_matrix(axis_angle_quaternion(np.array([0.0, math.pi / 2, 0.1])))[0]
    shift = 0.0123  # t_imu = t_cam + shift
    bias = np.array([0.01, -0.02, 0.005])
    t_imu = np.arange(0.0, 1.0, 0.001)
    gyro = omega_cam(t_imu - shift) @ r_cam_imu + bias  # rows: R^T w
    accel = np.tile([0.0, -9.81, 0.0], (len(t_imu), 1))
    write_imu(tmp_path / "imu.txt", t_imu, accel, gyro)
    source = read_gyroscope(tmp_path / "imu.txt", rotation_cam_imu=r_cam_imu, time_shift=shift, bias=bias)
    t = np.array([0.1, 0.2345, 0.5, 0.9])
    np.testing.assert_allclose(source.angular_velocity_at(t), omega_cam(t), atol=1e-12)
    # Without the shift the answer is off by the rate of change times the shift.
    wrong = Gyroscope(t_imu, gyro - bias, rotation_cam_imu=r_cam_imu).angular_velocity_at(t)
    assert np.abs(wrong - omega_cam(t)).max() > 0.01


def test_gyroscope_rejects_a_non_rotation():
    with pytest.raises(DataError, match="rotation matrix"):
        Gyroscope([0.0, 1.0], np.zeros((2, 3)), rotation_cam_imu=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(DataError, match="strictly increasing"):
        Gyroscope([0.0, 0.0], np.zeros((2, 3)))


def test_samples_round_trip_and_interpolate(tmp_path):
    times = np.array([0.0, 0.5, 1.0])
    omegas = np.array([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 2.0]])
    write_angular_velocity_samples(tmp_path / "w.txt", times, omegas)
    source = read_angular_velocity_samples(tmp_path / "w.txt")
    np.testing.assert_array_equal(source.omegas, omegas)
    np.testing.assert_allclose(source.angular_velocity_at([-1.0, 0.25, 0.75, 2.0]),
                               [[0, 1, 0], [0.5, 1, 0], [1, 0.5, 1], [1, 0, 2]])
    (tmp_path / "bad.txt").write_text("0 1 2 3\n0.1 1 nan 3\n")
    with pytest.raises(DataError, match="bad.txt:2"):
        read_angular_velocity_samples(tmp_path / "bad.txt")
    with pytest.raises(DataError, match="no angular velocity samples"):
        AngularVelocitySamples(np.zeros(0), np.zeros((0, 3)))


def test_constant():
    np.testing.assert_array_equal(ConstantAngularVelocity((0.1, 0.2, 0.3)).angular_velocity_at([0.0, 5.0]),
                                  [[0.1, 0.2, 0.3]] * 2)


def test_angular_velocity_of_a_recording(tmp_path):
    times = np.linspace(0, 1, 11)
    events = make_events([0, 10], [1, 2], [1, 1], [1, 0])
    intrinsics = Intrinsics(200.0, 200.0, 10.0, 10.0)
    still = np.tile([0.0, 0.0, 0.0, 1.0], (len(times), 1))
    write_ecd(tmp_path / "still", events, intrinsics=intrinsics, times=times, positions=np.zeros((11, 3)),
              quaternions=still)
    assert angular_velocity_of(read_ecd(tmp_path / "still")) is None  # poses that never turn: eq. 8
    turning = constant_rotation_poses((0.0, 0.4, 0.0), times)
    write_ecd(tmp_path / "turning", events, intrinsics=intrinsics, times=times, positions=np.zeros((11, 3)),
              quaternions=turning)
    write_imu(tmp_path / "turning" / "imu.txt", times, np.zeros((11, 3)), np.tile([0.0, 0.1, 0.0], (11, 1)))
    recording = read_ecd(tmp_path / "turning")
    np.testing.assert_allclose(angular_velocity_of(recording).angular_velocity_at(0.5), [[0, 0.4, 0]], atol=1e-12)
    np.testing.assert_allclose(angular_velocity_of(recording, prefer="gyro").angular_velocity_at(0.5), [[0, 0.1, 0]])
    gyro_only = Recording(events, imu=recording.imu)
    np.testing.assert_allclose(angular_velocity_of(gyro_only).angular_velocity_at(0.5), [[0, 0.1, 0]])
    with pytest.raises(DataError, match="'poses' or 'gyro'"):
        angular_velocity_of(recording, prefer="imu")
