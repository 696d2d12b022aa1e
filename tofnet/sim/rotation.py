"""A camera that turns as it moves, and the gyroscope riding on it.

``RotatingTrajectory`` adds an orientation to a translational ``Trajectory``:
``R_wc(t) = Ry(yaw) Rx(pitch) Rz(roll)`` (camera-to-world; yaw about the world's y
axis, which points down, so a positive yaw turns the camera right), each angle a
``Sway``: an offset, a constant rate and sinusoids, with exact derivatives. The
camera-frame angular velocity follows from ``[ω]× = R^T dR/dt``:
``ω = (Rx Rz)^T (0, yaw', 0) + Rz^T (pitch', 0, 0) + (0, 0, roll')``.

``ImuModel`` samples that motion as an ``imu.txt`` (ECD: ``t ax ay az gx gy gz``) in
the camera frame (the IMU sits at the camera, axes aligned, clocks equal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tofnet.io.rotation import quaternion_multiply
from tofnet.sim.camera import Trajectory
from tofnet.sim.errors import SimError

#: Gravity, m/s², along the world's +y (down).
GRAVITY = 9.81


@dataclass(frozen=True)
class Sway:
    """An angle over time, radians: ``offset + rate t + Σ a sin(2π f t + φ)`` for ``waves`` ``(a, f, φ)``.

    ``a`` in radians, ``f`` in Hz, ``φ`` in radians; ``rate`` in rad/s.
    """

    offset: float = 0.0
    rate: float = 0.0
    waves: tuple[tuple[float, float, float], ...] = ()

    def __post_init__(self) -> None:
        values = [self.offset, self.rate] + [v for wave in self.waves for v in wave]
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values) or \
                any(len(wave) != 3 for wave in self.waves):
            raise SimError(f"sway: expected finite offset, rate and waves (amplitude rad, frequency Hz, phase rad), "
                           f"got {self!r}")

    def angle(self, t: np.ndarray) -> np.ndarray:
        """The angle (rad) at times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        out = self.offset + self.rate * t
        for amplitude, frequency, phase in self.waves:
            out = out + amplitude * np.sin(2 * math.pi * frequency * t + phase)
        return out

    def derivative(self, t: np.ndarray) -> np.ndarray:
        """d angle / dt (rad/s) at times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        out = np.full(t.shape, float(self.rate))
        for amplitude, frequency, phase in self.waves:
            out = out + amplitude * 2 * math.pi * frequency * np.cos(2 * math.pi * frequency * t + phase)
        return out

    @property
    def max_rate(self) -> float:
        """An upper bound of ``|d angle / dt|``, rad/s."""
        return abs(self.rate) + sum(abs(a) * 2 * math.pi * abs(f) for a, f, _ in self.waves)


def _axis_quaternions(axis: int, angles: np.ndarray) -> np.ndarray:
    q = np.zeros((angles.shape[0], 4))
    q[:, axis] = np.sin(angles / 2)
    q[:, 3] = np.cos(angles / 2)
    return q


def _axis_matrices(axis: int, angles: np.ndarray) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    m = np.zeros((angles.shape[0], 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]  # the plane the rotation turns: x: (y, z), y: (z, x), z: (x, y)
    m[:, axis, axis] = 1.0
    m[:, i, i], m[:, j, j] = c, c
    m[:, i, j], m[:, j, i] = -s, s
    return m


@dataclass(frozen=True)
class RotatingTrajectory:
    """A translational ``Trajectory`` (positions in the world, m) with a turning orientation.

    Implements ``VelocitySource`` (``velocity_at``: camera frame, ``R_wc^T dp/dt``) and
    ``AngularVelocitySource`` (``angular_velocity_at``: camera frame, rad/s).
    """

    translation: Trajectory
    yaw: Sway = Sway()
    pitch: Sway = Sway()
    roll: Sway = Sway()

    #: The simulator renders it with ``tofnet.sim.engine_rotating``.
    rotates = True

    @property
    def start(self):
        return self.translation.start

    @property
    def segments(self):
        return self.translation.segments

    @property
    def boundaries(self) -> np.ndarray:
        return self.translation.boundaries

    def position_at(self, t: np.ndarray) -> np.ndarray:
        """Camera centre (m, world, ``(n, 3)``) at times ``t`` (s)."""
        return self.translation.position_at(t)

    def world_velocity_at(self, t: np.ndarray) -> np.ndarray:
        """``dp/dt`` (m/s, world frame, ``(n, 3)``)."""
        return self.translation.velocity_at(t)

    def _angles(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return self.yaw.angle(t), self.pitch.angle(t), self.roll.angle(t)

    def rotation_at(self, t: np.ndarray) -> np.ndarray:
        """``R_wc`` (camera-to-world, ``(n, 3, 3)``) at times ``t`` (s)."""
        yaw, pitch, roll = self._angles(t)
        return _axis_matrices(1, yaw) @ _axis_matrices(0, pitch) @ _axis_matrices(2, roll)

    def quaternion_at(self, t: np.ndarray) -> np.ndarray:
        """``R_wc`` as unit quaternions ``qx qy qz qw`` (``(n, 4)``), as ``groundtruth.txt`` stores them."""
        yaw, pitch, roll = self._angles(t)
        return quaternion_multiply(quaternion_multiply(_axis_quaternions(1, yaw), _axis_quaternions(0, pitch)),
                                   _axis_quaternions(2, roll))

    def angular_velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Camera-frame angular velocity (rad/s, ``(n, 3)``) at times ``t`` (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        _, pitch, roll = self._angles(t)
        rx, rz = _axis_matrices(0, pitch), _axis_matrices(2, roll)
        zeros = np.zeros(t.shape[0])
        yaw_rate = np.column_stack([zeros, self.yaw.derivative(t), zeros])
        pitch_rate = np.column_stack([self.pitch.derivative(t), zeros, zeros])
        # Rows times matrices: v @ M = M^T v.
        omega = np.einsum("ni,nij->nj", yaw_rate, rx @ rz) + np.einsum("ni,nij->nj", pitch_rate, rz)
        omega[:, 2] += self.roll.derivative(t)
        return omega

    def velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Camera-frame translational velocity ``R_wc^T dp/dt`` (m/s, ``(n, 3)``)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return np.einsum("ni,nij->nj", self.world_velocity_at(t), self.rotation_at(t))

    @property
    def max_angular_speed(self) -> float:
        """An upper bound of ``|ω|``, rad/s."""
        return math.sqrt(self.yaw.max_rate ** 2 + self.pitch.max_rate ** 2 + self.roll.max_rate ** 2)


@dataclass(frozen=True)
class ImuModel:
    """An IMU at the camera (same axes and clock) sampled ``rate`` times a second.

    The gyroscope reads the true camera-frame angular velocity plus ``gyro_bias``
    (rad/s, constant) plus white noise of density ``gyro_noise_density``
    (rad/s/√Hz, i.e. a standard deviation of ``density * sqrt(rate)`` per sample).
    The accelerometer reads the specific force ``R_wc^T (a − g)`` in m/s²; the
    simulated velocity is piecewise constant, so ``a = 0`` and it reads gravity only
    (``g`` along the world's +y, down).
    """

    rate: float = 1000.0
    gyro_noise_density: float = 0.0
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise SimError(f"imu rate: expected a positive number of samples per second, got {self.rate!r}")
        if not (math.isfinite(self.gyro_noise_density) and self.gyro_noise_density >= 0):
            raise SimError(f"imu gyro_noise_density: expected a number >= 0 (rad/s/sqrt(Hz)), "
                           f"got {self.gyro_noise_density!r}")
        if len(self.gyro_bias) != 3 or not all(math.isfinite(v) for v in self.gyro_bias):
            raise SimError(f"imu gyro_bias: expected 3 finite rad/s values, got {self.gyro_bias!r}")

    def sample(self, trajectory, duration: float, rng: np.random.Generator) -> np.ndarray:
        """``imu.txt`` rows ``t ax ay az gx gy gz`` (s, m/s², rad/s) from 0 to ``duration`` s."""
        t = np.arange(int(math.floor(duration * self.rate + 1e-9)) + 1) / self.rate
        if getattr(trajectory, "rotates", False):
            rotation = trajectory.rotation_at(t)
            omega = trajectory.angular_velocity_at(t)
        else:
            rotation = np.broadcast_to(np.eye(3), (t.shape[0], 3, 3))
            omega = np.zeros((t.shape[0], 3))
        specific_force = np.einsum("i,nij->nj", np.array([0.0, -GRAVITY, 0.0]), rotation)
        sigma = self.gyro_noise_density * math.sqrt(self.rate)
        noise = rng.normal(0.0, sigma, size=omega.shape) if sigma > 0 else 0.0
        gyro = omega + np.asarray(self.gyro_bias, dtype=np.float64) + noise
        return np.column_stack([t, specific_force, gyro])


def imu_samples(config, seed: int) -> np.ndarray | None:
    """The ``imu.txt`` rows of ``config`` (``config.imu``), or None when it has no IMU.

    The gyroscope noise has its own random stream (``[seed, 104729, 2]``), so adding an
    IMU changes none of the events.
    """
    if config.imu is None:
        return None
    return config.imu.sample(config.trajectory, config.duration, np.random.default_rng([seed, 104729, 2]))
