"""The camera's angular velocity: from poses, a gyroscope, samples, or a constant.

Every source has ``angular_velocity_at(t) -> (n, 3)``: rad/s in the camera frame
(x right, y down, z forward) at times ``t`` in seconds, the ``ω`` of paper eq. 7
(``docs/rotation.md``). Sign: a camera turning right (about +y, which points down)
has ``ωy > 0`` and sees the scene move left.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.groundtruth import Trajectory, _check_times, _first, _write_rows, quaternion_to_matrix, read_table

#: Below this half-angle sine, ``2 atan2(s, w) / s`` is replaced by its limit ``2 / w``
#: (relative error below 1e-16 there); it avoids 0/0 for two equal orientations.
_SMALL_SINE = 1e-9
#: Poses whose orientations all lie within this angle (radians) of the first one do not rotate.
STILL_ANGLE = 1e-6


class AngularVelocitySource(Protocol):
    """Anything that gives the camera's angular velocity in the camera frame."""

    def angular_velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Angular velocity (rad/s, camera frame, shape ``(n, 3)``) at times ``t`` (seconds)."""
        ...


@dataclass(frozen=True)
class ConstantAngularVelocity:
    """A camera turning at one rate ``(wx, wy, wz)`` rad/s in the camera frame."""

    omega: tuple[float, float, float]

    def angular_velocity_at(self, t: np.ndarray) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return np.broadcast_to(np.asarray(self.omega, dtype=np.float64), (t.shape[0], 3)).copy()


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products ``a ⊗ b`` of quaternion rows ordered ``qx qy qz qw`` (``R(a ⊗ b) = R(a) R(b)``)."""
    ax, ay, az, aw = (a[:, k] for k in range(4))
    bx, by, bz, bw = (b[:, k] for k in range(4))
    return np.column_stack([aw * bx + ax * bw + ay * bz - az * by,
                            aw * by - ax * bz + ay * bw + az * bx,
                            aw * bz + ax * by - ay * bx + az * bw,
                            aw * bw - ax * bx - ay * by - az * bz])


def relative_rotation_vector(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Rotation vectors ``θ k`` (rad, ``(n, 3)``) of ``R0^T R1`` for unit quaternion rows, the short way round.

    ``k`` is in the frame of the first pose: the body frame. Uses ``θ = 2 atan2(|v|, w)``
    of ``q0* ⊗ q1 = (v, w)``, accurate from 0 to π (``arccos`` is not near 0).
    """
    conjugate = q0 * np.array([-1.0, -1.0, -1.0, 1.0])
    rel = quaternion_multiply(conjugate, q1)
    rel[rel[:, 3] < 0] *= -1  # q and -q are one rotation: take w >= 0, the shorter way
    vector, w = rel[:, :3], rel[:, 3]
    sine = np.linalg.norm(vector, axis=1)
    scale = np.empty_like(sine)
    small = sine < _SMALL_SINE
    scale[~small] = 2.0 * np.arctan2(sine[~small], w[~small]) / sine[~small]
    scale[small] = 2.0 / w[small]
    return vector * scale[:, None]


class PoseAngularVelocity:
    """The angular velocity of ground-truth poses: the derivative of ``Trajectory``'s slerp.

    Between two poses the slerp turns at a constant rate about a fixed body axis,
    ``R(t) = R_i exp((t − t_i)/(t_i+1 − t_i) [θ k]×)``, so the camera-frame angular
    velocity (``[ω]× = R^T dR/dt``) is ``θ k / (t_i+1 − t_i)`` over the whole segment.
    Outside the recorded range the first/last segment's, like ``Trajectory.velocity_at``
    (the poses themselves are held there).
    """

    def __init__(self, trajectory: Trajectory) -> None:
        self.trajectory = trajectory
        times = trajectory.times
        q = trajectory.quaternions
        self._rates = relative_rotation_vector(q[:-1], q[1:]) / np.diff(times)[:, None]

    @property
    def rotates(self) -> bool:
        """True when some pose turns more than ``STILL_ANGLE`` away from the first."""
        q = self.trajectory.quaternions
        angles = np.linalg.norm(relative_rotation_vector(np.repeat(q[:1], len(q), axis=0), q), axis=1)
        return bool(np.any(angles > STILL_ANGLE))

    def angular_velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Angular velocity (rad/s, camera frame, ``(n, 3)``) at times ``t`` (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        times = self.trajectory.times
        segment = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
        return self._rates[segment].copy()


class AngularVelocitySamples:
    """Camera-frame angular velocity samples, linearly interpolated, end values outside the range.

    Parameters
    ----------
    times : (n,) seconds, strictly increasing, n >= 1.
    omegas : (n, 3) rad/s in the camera frame.
    """

    def __init__(self, times, omegas, source: object = "<memory>", lines: np.ndarray | None = None,
                 what: str = "angular velocity sample"):
        times = np.asarray(times, dtype=np.float64)
        omegas = np.asarray(omegas, dtype=np.float64)
        if times.ndim != 1 or omegas.shape != (times.shape[0], 3):
            raise DataError(located(source, None, f"{what}s need times (n,) and rates (n, 3); "
                                                  f"got {times.shape} and {omegas.shape}"))
        if times.shape[0] == 0:
            raise DataError(located(source, None, f"no {what}s"))
        bad = _first(~(np.isfinite(times) & np.all(np.isfinite(omegas), axis=1)))
        if bad is not None:
            where = int(lines[bad]) if lines is not None else None
            raise DataError(located(source, where, f"{what} is not finite (NaN or inf)"))
        _check_times(times, source, lines, what)
        self.times = times
        self.omegas = omegas
        self.source = source

    def angular_velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Angular velocity (rad/s, camera frame, ``(n, 3)``) at times ``t`` (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return np.column_stack([np.interp(t, self.times, self.omegas[:, k]) for k in range(3)])


def read_angular_velocity_samples(path: str | Path) -> AngularVelocitySamples:
    """Read ``t wx wy wz`` lines (s, rad/s in the camera frame)."""
    values, lines = read_table(path, ("t", "wx", "wy", "wz"), "angular velocity sample")
    return AngularVelocitySamples(values[:, 0], values[:, 1:4], source=Path(path), lines=lines)


def write_angular_velocity_samples(path: str | Path, times, omegas) -> None:
    """Write ``t wx wy wz`` lines (s, rad/s in the camera frame), exactly round-tripping floats."""
    samples = AngularVelocitySamples(times, omegas, source=Path(path))
    _write_rows(path, np.column_stack([samples.times, samples.omegas]), "# t wx wy wz  (s, rad/s, camera frame)")


class Gyroscope(AngularVelocitySamples):
    """Gyroscope samples turned into the camera's angular velocity.

    ``ω_cam(t) = R_cam_imu (g(t + time_shift) − bias)``, ``g`` linearly interpolated
    between samples (end values outside them).

    Parameters
    ----------
    times : (n,) IMU timestamps, seconds.
    gyro : (n, 3) rad/s in the IMU frame (``gx gy gz`` of ``imu.txt``).
    rotation_cam_imu : 3x3 rotation taking IMU-frame vectors to the camera frame
        (Kalibr's ``T_cam_imu`` rotation part); identity by default.
    time_shift : seconds, Kalibr's ``timeshift_cam_imu``: ``t_imu = t_cam + time_shift``.
    bias : rad/s in the IMU frame, subtracted from every sample.
    """

    def __init__(self, times, gyro, *, rotation_cam_imu=None, time_shift: float = 0.0,
                 bias=(0.0, 0.0, 0.0), source: object = "<memory>", lines: np.ndarray | None = None):
        super().__init__(times, gyro, source=source, lines=lines, what="gyroscope sample")
        rotation = np.eye(3) if rotation_cam_imu is None else np.asarray(rotation_cam_imu, dtype=np.float64)
        if rotation.shape != (3, 3) or not np.all(np.isfinite(rotation)):
            raise DataError(located(source, None, f"rotation_cam_imu: expected a finite 3x3 matrix, "
                                                  f"got shape {rotation.shape}"))
        _check_rotation(rotation, located(source, None, "rotation_cam_imu"))
        bias = np.asarray(bias, dtype=np.float64)
        if bias.shape != (3,) or not np.all(np.isfinite(bias)):
            raise DataError(located(source, None, f"gyroscope bias: expected 3 finite rad/s values, got {bias!r}"))
        if not np.isfinite(time_shift):
            raise DataError(located(source, None, f"time_shift: expected a finite number of seconds, "
                                                  f"got {time_shift!r}"))
        self.rotation_cam_imu = rotation
        self.time_shift = float(time_shift)
        self.bias = bias

    def angular_velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Angular velocity (rad/s, camera frame, ``(n, 3)``) at camera times ``t`` (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        imu = super().angular_velocity_at(t + self.time_shift) - self.bias
        return imu @ self.rotation_cam_imu.T


def _check_rotation(matrix: np.ndarray, what: str) -> None:
    if not np.allclose(matrix @ matrix.T, np.eye(3), atol=1e-6) or np.linalg.det(matrix) < 0:
        raise DataError(f"{what}: expected a rotation matrix (orthonormal, determinant +1)")


def rotation_matrix(values, what: str = "rotation_cam_imu") -> np.ndarray:
    """A 3x3 rotation from 9 numbers (the matrix row by row) or 4 (a unit quaternion ``qx qy qz qw``).

    The quaternion's order is ``groundtruth.txt``'s and ROS's; it may be off unit length by
    1e-6 (it is normalised). Anything else is a ``DataError`` naming ``what``.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if not np.all(np.isfinite(v)):
        raise DataError(f"{what}: expected finite numbers, got {list(values)}")
    if v.shape == (4,):
        norm = float(np.linalg.norm(v))
        if abs(norm - 1.0) > 1e-6:
            raise DataError(f"{what}: a quaternion qx qy qz qw must have unit length, got |q| = {norm:.6g}")
        return quaternion_to_matrix(v / norm)[0]
    if v.shape == (9,):
        matrix = v.reshape(3, 3)
        _check_rotation(matrix, what)
        return matrix
    raise DataError(f"{what}: expected 9 numbers (a 3x3 rotation, row by row) or 4 (a quaternion qx qy qz qw), "
                    f"got {v.size}")


def gyroscope_from_imu(imu: np.ndarray, *, source: object = "<memory>", **options) -> Gyroscope:
    """A ``Gyroscope`` from an ``imu.txt`` table ``t ax ay az gx gy gz`` (``tofnet.io.ecd.read_imu``)."""
    imu = np.asarray(imu, dtype=np.float64)
    if imu.ndim != 2 or imu.shape[1] != 7:
        raise DataError(located(source, None, f"IMU samples: expected rows 't ax ay az gx gy gz', "
                                              f"got shape {imu.shape}"))
    return Gyroscope(imu[:, 0], imu[:, 4:7], source=source, **options)


def read_gyroscope(path: str | Path, **options) -> Gyroscope:
    """The gyroscope of an ECD ``imu.txt`` (read with ``tofnet.io.ecd.read_imu``); ``options`` as ``Gyroscope``."""
    from tofnet.io.ecd import read_imu

    return gyroscope_from_imu(read_imu(path), source=Path(path), **options)


def write_imu(path: str | Path, times, accelerometer, gyroscope) -> None:
    """Write ECD ``imu.txt``: ``t ax ay az gx gy gz`` (s, m/s², rad/s), exactly round-tripping floats."""
    times = np.asarray(times, dtype=np.float64)
    rows = np.column_stack([times, np.asarray(accelerometer, dtype=np.float64).reshape(-1, 3),
                            np.asarray(gyroscope, dtype=np.float64).reshape(-1, 3)])
    AngularVelocitySamples(times, rows[:, 4:7], source=Path(path), what="gyroscope sample")  # checks
    _write_rows(path, rows, "# t ax ay az gx gy gz  (s, m/s^2, rad/s)")


def angular_velocity_of(recording, *, prefer: str = "poses", **gyro_options) -> AngularVelocitySource | None:
    """The recording's rotation information, or None when it has none.

    ``prefer="poses"``: ground-truth poses that rotate (``PoseAngularVelocity.rotates``),
    else the gyroscope of ``imu.txt``; ``prefer="gyro"`` the other way round. Poses
    that never turn, and no IMU, give None (eq. 8 applies).
    """
    if prefer not in ("poses", "gyro"):
        raise DataError(f"rotation source: expected 'poses' or 'gyro', got {prefer!r}")
    poses = None
    if isinstance(recording.trajectory, Trajectory):
        candidate = PoseAngularVelocity(recording.trajectory)
        poses = candidate if candidate.rotates else None
    gyro = None
    if recording.imu is not None and len(recording.imu):
        gyro = gyroscope_from_imu(recording.imu, source=recording.source, **gyro_options)
    first, second = (poses, gyro) if prefer == "poses" else (gyro, poses)
    return first if first is not None else second
