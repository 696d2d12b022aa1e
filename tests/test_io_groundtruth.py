"""Ground-truth poses, camera-frame velocity, velocity samples and calibration files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.io.calibration import read_calibration, write_calibration
from tofnet.io.groundtruth import (Trajectory, VelocitySamples, quaternion_to_matrix, read_groundtruth,
                                   read_velocity_samples, write_groundtruth, write_velocity_samples)
from tofnet.io.recording import Intrinsics

S = math.sqrt(0.5)
YAW_90 = (0.0, 0.0, S, S)  # qx qy qz qw: 90° about world z
IDENTITY = (0.0, 0.0, 0.0, 1.0)


def test_quaternion_to_matrix_90_degrees_about_z():
    r = quaternion_to_matrix(np.array([YAW_90]))[0]
    assert np.allclose(r, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])


def test_moving_along_world_x_while_yawed_90_degrees():
    # R_wc maps camera x to world y and camera y to world -x, so world +x motion is
    # camera -y motion: v_c = R_wc^T (1, 0, 0) = (0, -1, 0).
    trajectory = Trajectory([0.0, 1.0, 2.0], [[0, 0, 0], [1, 0, 0], [2, 0, 0]], [YAW_90] * 3)
    v = trajectory.velocity_at(np.array([0.0, 0.5, 1.5, 2.0]))
    assert v.shape == (4, 3)
    assert np.allclose(v, [[0, -1, 0]] * 4)


def test_velocity_is_the_segment_velocity_and_clamps_outside():
    trajectory = Trajectory([0.0, 1.0, 3.0], [[0, 0, 0], [2, 0, 0], [2, 0, 4]], [IDENTITY] * 3)
    v = trajectory.velocity_at(np.array([-5.0, 0.0, 0.99, 1.0, 2.0, 3.0, 10.0]))
    assert np.allclose(v[:, 0], [2, 2, 2, 0, 0, 0, 0])
    assert np.allclose(v[:, 2], [0, 0, 0, 2, 2, 2, 2])


def test_rotation_is_slerped_between_poses():
    trajectory = Trajectory([0.0, 1.0], [[0, 0, 0], [0, 0, 1]], [IDENTITY, YAW_90])
    positions, rotations = trajectory.pose_at(np.array([0.5, 2.0]))
    angle = math.radians(45)
    assert np.allclose(rotations[0], [[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0],
                                      [0, 0, 1]])
    assert np.allclose(rotations[1], quaternion_to_matrix(np.array([YAW_90]))[0])  # held after the end
    assert np.allclose(positions, [[0, 0, 0.5], [0, 0, 2.0]])  # extrapolated along the last segment
    # Optical axis z is unchanged by a yaw, so forward motion stays forward.
    assert np.allclose(trajectory.velocity_at(np.array([0.5])), [[0, 0, 1]])


def test_opposite_sign_quaternions_take_the_short_path():
    trajectory = Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]], [IDENTITY, (0, 0, -S, -S)])
    _, rotations = trajectory.pose_at(np.array([0.5]))
    assert np.allclose(rotations[0][0, 0], math.cos(math.radians(45)))


GT_TEXT = """# timestamp px py pz qx qy qz qw
0.000000000 0.0 0.0 0.0 0.0 0.0 0.0 1.0
0.500000000 0.1 0.0 0.0 0.0 0.0 0.0 1.0
1.000000000 0.2 0.0 0.0 0.0 0.0 0.0 1.0
"""


def test_read_groundtruth_and_round_trip(tmp_path):
    (tmp_path / "groundtruth.txt").write_text(GT_TEXT)
    trajectory = read_groundtruth(tmp_path / "groundtruth.txt")
    assert len(trajectory) == 3
    assert np.allclose(trajectory.velocity_at(np.array([0.25, 0.75])), [[0.2, 0, 0]] * 2)
    rng = np.random.default_rng(0)
    times = np.cumsum(rng.uniform(0.001, 0.01, 20))
    positions = rng.normal(size=(20, 3))
    quaternions = rng.normal(size=(20, 4))
    write_groundtruth(tmp_path / "out.txt", times, positions, quaternions)
    back = read_groundtruth(tmp_path / "out.txt")
    assert np.array_equal(back.times, times) and np.array_equal(back.positions, positions)
    assert np.allclose(back.quaternions, quaternions / np.linalg.norm(quaternions, axis=1, keepdims=True))


@pytest.mark.parametrize("text, line, message", [
    (GT_TEXT + "1.5 0.3 0 0 0 0 0\n", 5, "expected 8 columns 't px py pz qx qy qz qw'"),
    (GT_TEXT + "1.5 0.3 nan 0 0 0 0 1\n", 5, "column 'py': expected a finite number"),
    (GT_TEXT + "1.5 0.3 inf 0 0 0 0 1\n", 5, "column 'py': expected a finite number"),
    (GT_TEXT + "1.5 0.3 0 x 0 0 0 1\n", 5, "column 'pz': expected a number, got 'x'"),
    (GT_TEXT + "1.0 0.3 0 0 0 0 0 1\n", 5, "strictly increasing"),
    (GT_TEXT + "0.7 0.3 0 0 0 0 0 1\n", 5, "strictly increasing"),
    (GT_TEXT + "1.5 0.3 0 0 0 0 0 0\n", 5, "quaternion qx qy qz qw is zero"),
])
def test_groundtruth_errors_name_file_and_line(tmp_path, text, line, message):
    path = tmp_path / "groundtruth.txt"
    path.write_text(text)
    with pytest.raises(DataError, match=f"groundtruth.txt:{line}: .*{message}"):
        read_groundtruth(path)


def test_fewer_than_two_poses(tmp_path):
    (tmp_path / "groundtruth.txt").write_text("0.0 0 0 0 0 0 0 1\n")
    with pytest.raises(DataError, match="groundtruth.txt: need at least 2 poses"):
        read_groundtruth(tmp_path / "groundtruth.txt")


def test_trajectory_from_arrays_names_the_pose():
    with pytest.raises(DataError, match="pose 1: pose is not finite"):
        Trajectory([0, 1], [[0, 0, 0], [np.nan, 0, 0]], [IDENTITY] * 2)
    with pytest.raises(DataError, match="positions \\(n, 3\\)"):
        Trajectory([0, 1], [[0, 0], [0, 0]], [IDENTITY] * 2)


def test_velocity_samples_interpolate_and_clamp(tmp_path):
    samples = VelocitySamples([0.0, 1.0], [[0, 0, 1], [2, 0, 1]])
    v = samples.velocity_at(np.array([-1.0, 0.25, 5.0]))
    assert np.allclose(v, [[0, 0, 1], [0.5, 0, 1], [2, 0, 1]])
    write_velocity_samples(tmp_path / "v.txt", [0.0, 0.1, 0.3], [[1, 2, 3], [4, 5, 6], [7, 8, 9.5]])
    back = read_velocity_samples(tmp_path / "v.txt")
    assert np.array_equal(back.velocities, [[1, 2, 3], [4, 5, 6], [7, 8, 9.5]])
    (tmp_path / "bad.txt").write_text("0 1 2 3\n0.1 1 2\n")
    with pytest.raises(DataError, match="bad.txt:2: expected 4 columns 't vx vy vz'"):
        read_velocity_samples(tmp_path / "bad.txt")
    (tmp_path / "empty.txt").write_text("# nothing\n")
    with pytest.raises(DataError, match="empty.txt: no velocity samples"):
        read_velocity_samples(tmp_path / "empty.txt")


SLIDER_CALIB = ("335.419462958 335.352935775 129.924663379 92.1864667189 -0.138592767408 0.0933736664192 "
                "-0.000335586987532 0.000173720158228 0.0\n")


def test_read_calibration_nine_and_four_numbers(tmp_path):
    (tmp_path / "calib.txt").write_text(SLIDER_CALIB)
    intrinsics = read_calibration(tmp_path / "calib.txt")
    assert (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy) == (
        335.419462958, 335.352935775, 129.924663379, 92.1864667189)
    assert len(intrinsics.distortion) == 5 and intrinsics.distortion[0] == -0.138592767408
    (tmp_path / "four.txt").write_text("# pinhole\n200 200 120 90\n")
    assert read_calibration(tmp_path / "four.txt") == Intrinsics(200.0, 200.0, 120.0, 90.0)


@pytest.mark.parametrize("intrinsics", [Intrinsics(200.5, 201.25, 119.5, 89.5),
                                        Intrinsics(335.4, 335.3, 129.9, 92.1, (-0.1, 0.09, -3e-4, 1e-4, 0.0))])
def test_calibration_round_trip(tmp_path, intrinsics):
    write_calibration(tmp_path / "calib.txt", intrinsics)
    assert read_calibration(tmp_path / "calib.txt") == intrinsics


@pytest.mark.parametrize("text, message", [
    ("200 200 120\n", ":1: expected 4 numbers"),
    ("200 200 120 90 1\n", ":1: expected 4 numbers"),
    ("200 abc 120 90\n", ":1: 'fy': expected a number"),
    ("200 200 nan 90\n", ":1: 'cx': expected a finite number"),
    ("-200 200 120 90\n", ":1: focal lengths must be positive"),
    ("200 200 120 90\n1 1 1 1\n", ":2: expected one line"),
    ("", ": empty calibration"),
])
def test_calibration_errors(tmp_path, text, message):
    (tmp_path / "calib.txt").write_text(text)
    with pytest.raises(DataError, match=f"calib.txt{message}"):
        read_calibration(tmp_path / "calib.txt")
