"""Binding a process to a recording: the camera (intrinsics, lens) and the velocities it reads,
sampled at its updates (the velocity models and the fused stream)."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from tofnet.errors import BackendError, DataError
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording, VelocitySource
from tofnet.units import seconds_of


def intrinsics_of(given, recording: Recording | None, who: str) -> Intrinsics:
    """Intrinsics ``given`` by a process (``[fx, fy, cx, cy]``), else the recording's calibration."""
    if given is not None:
        fx, fy, cx, cy = given
        return Intrinsics(fx, fy, cx, cy)
    if recording is None or recording.intrinsics is None:
        source = recording.source if recording is not None else "the stream"
        raise DataError(f"{source}: no camera calibration (calib.txt); the process '{who}' needs fx, fy, cx, cy: "
                        "pass --intrinsics FX,FY,CX,CY or --calib FILE (plan keys intrinsics:, calib:), add "
                        "calib.txt beside the recording, or set intrinsics: [fx, fy, cx, cy] in the spec")
    return recording.intrinsics


def camera_of(intrinsics, distortion_model: str | None, distortion, recording: Recording | None,
              who: str) -> Intrinsics:
    """The camera a velocity process sees: its intrinsics (``intrinsics_of``) and its lens: the given
    ``distortion`` (with ``distortion_model``), none for ``distortion_model: none``, else the
    recording's calibration when the intrinsics come from it."""
    camera = intrinsics_of(intrinsics, recording, who)
    if distortion_model == "none":
        return Intrinsics(camera.fx, camera.fy, camera.cx, camera.cy)
    if distortion is not None:
        coefficients = tuple(float(c) for c in distortion)
        if distortion_model == "radtan" and len(coefficients) == 4:
            coefficients += (0.0,)  # k3
        return Intrinsics(camera.fx, camera.fy, camera.cx, camera.cy, coefficients, distortion_model)
    return camera


def velocity_source_of(source: str, constant, samples: str | None, recording: Recording | None,
                       who: str) -> VelocitySource:
    """The camera velocity a velocity process reads: ``constant``, ``samples`` (a file) or ``groundtruth``."""
    if source == "constant":
        return ConstantVelocity(tuple(constant))
    if source == "samples":
        from tofnet.io.groundtruth import read_velocity_samples
        return read_velocity_samples(samples)
    if recording is None or recording.trajectory is None:
        where = recording.source if recording is not None else "the stream"
        raise DataError(f"{where}: no ground-truth poses (groundtruth.txt), so process '{who}' cannot know the "
                        "camera's velocity: pass --velocity VX,VY,VZ (m/s, camera frame; plan key velocity:) or "
                        f"--set {who}.source=samples --set {who}.samples=FILE, add groundtruth.txt beside the "
                        "recording, or set source: constant/samples in the spec")
    return recording.trajectory


def update_times(t0_us: int, timestep_us: int, update_every: int, n_updates: int, first_update: int = 0) -> np.ndarray:
    """Seconds at which updates ``first_update ...`` of a host field sample their source.

    Update j is sent in step ``j * update_every`` and samples its source at that step's
    start, ``t0 + j * update_every * timestep``.
    """
    j = np.arange(first_update, first_update + n_updates, dtype=np.int64)
    return seconds_of(t0_us + j * update_every * timestep_us)


def _checked_table(source: Callable[[np.ndarray], Any], t: np.ndarray, what: str, where: str) -> np.ndarray:
    # Huge finite inputs (a gyro sample of 1.797e308 minus a bias) overflow on the way; the
    # result is checked below, so numpy's RuntimeWarning would only come before the one line.
    with np.errstate(over="ignore", invalid="ignore"):
        table = np.ascontiguousarray(source(t), dtype=np.float64)
    if table.shape != (len(t), 3):
        raise BackendError(f"{what} source returned shape {table.shape}, expected ({len(t)}, 3)")
    if not np.all(np.isfinite(table)):
        bad = t[~np.all(np.isfinite(table), axis=1)][0]
        raise DataError(f"{what} is not finite at t = {bad:.6f} s (check the {where})")
    return table


def velocity_table(source: VelocitySource, t0_us: int, timestep_us: int, update_every: int,
                   n_updates: int, first_update: int = 0) -> np.ndarray:
    """Camera velocity (m/s, shape ``(n_updates, 3)``) of updates ``first_update ...`` (``update_times``)."""
    t = update_times(t0_us, timestep_us, update_every, n_updates, first_update)
    return _checked_table(source.velocity_at, t, "camera velocity", "poses or samples")


def angular_velocity_table(source, t0_us: int, timestep_us: int, update_every: int,
                           n_updates: int, first_update: int = 0) -> np.ndarray:
    """Angular velocity (rad/s, camera frame, ``(n_updates, 3)``) of updates ``first_update ...`` (``update_times``)."""
    t = update_times(t0_us, timestep_us, update_every, n_updates, first_update)
    return _checked_table(source.angular_velocity_at, t, "angular velocity", "poses, samples or IMU")


class UpdateRows:
    """The updates of a host field, computed ``lookahead`` updates ahead of the clock and cached.

    ``table(first, count)`` computes rows ``first .. first+count-1``; when the rows past the
    ones asked for cannot be computed (e.g. not finite beyond the recording), only those asked
    for are. Shared by the velocity and angular velocity models and the fused stream.
    """

    def __init__(self, table: Callable[[int, int], np.ndarray], lookahead: int = 1024):
        self._table = table
        self.lookahead = lookahead
        self._cached: tuple[int, np.ndarray] = (0, np.zeros((0, 3)))

    def rows(self, first: int, count: int) -> tuple[np.ndarray, int]:
        """A table whose row ``i`` is update ``start + i``, covering ``first .. first+count-1``; and ``start``."""
        start, table = self._cached
        if start <= first and first + count <= start + len(table):
            return table, start
        try:
            table = self._table(first, max(count, self.lookahead))
        except (BackendError, DataError):
            table = self._table(first, count)
        self._cached = (first, table)
        return table, first

    def clear(self) -> None:
        """Forget the cached rows (the source changed): the next request computes them anew."""
        self._cached = (0, np.zeros((0, 3)))

    def slice(self, first: int, count: int) -> np.ndarray:
        """Rows ``first .. first+count-1`` exactly."""
        table, start = self.rows(first, count)
        return table[first - start:first - start + count]
