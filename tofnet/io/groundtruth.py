"""Camera motion: ECD ground-truth poses and camera-frame velocity samples.

Also the small whitespace-separated numeric tables every ECD side file uses
(``groundtruth.txt``, ``imu.txt``, ``calib.txt``, velocity samples): ``read_table``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, quote_field
from tofnet.events import MAX_TIME_US
from tofnet.io import files

#: Below this angle between two samples (radians) slerp falls back to normalised lerp,
#: where ``sin(angle)`` would lose precision.
_SLERP_MIN_ANGLE = 1e-6


def read_text(path: str | Path) -> str:
    """The UTF-8 text of a regular file, or a ``DataError`` saying why it cannot be read."""
    return files.read_text(path)


def read_table(path: str | Path, names: tuple[str, ...], what: str) -> tuple[np.ndarray, np.ndarray]:
    """Parse a whitespace-separated table of numbers, one row per line.

    Blank lines and lines starting with ``#`` are skipped; commas count as spaces.
    Every value must be a finite number.

    Parameters
    ----------
    path : file to read.
    names : column names, used in the expected-format message (``t px py pz ...``).
    what : what one row holds, for error messages ("pose").

    Returns
    -------
    values : float64 array of shape ``(rows, len(names))``.
    lines : int64 array, the 1-based line number of each row.
    """
    text = read_text(path)
    rows: list[list[float]] = []
    lines: list[int] = []
    expected = " ".join(names)
    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = stripped.replace(",", " ").split()
        if len(fields) != len(names):
            # The line itself is not quoted: the file may not be a table at all.
            raise DataError(located(path, number, f"expected {len(names)} columns '{expected}' per {what}, "
                                                  f"found {len(fields)}"))
        rows.append([finite_number(path, number, f"column '{name}'", field) for name, field in zip(names, fields)])
        lines.append(number)
    values = np.asarray(rows, dtype=np.float64).reshape(len(rows), len(names))
    return values, np.asarray(lines, dtype=np.int64)


def finite_number(path: object, line: int, what: str, field: str) -> float:
    """``field`` as a float, or a ``DataError`` naming the file, line and ``what`` (NaN and inf refused)."""
    try:
        value = float(field) if len(field) <= 1000 else math.nan
    except ValueError:
        raise DataError(located(path, line, f"{what}: expected a number, got {quote_field(path, field)}")) from None
    if not math.isfinite(value):
        raise DataError(located(path, line, f"{what}: expected a finite number, got {quote_field(path, field)}"))
    return value


def _check_times(times: np.ndarray, source: object, lines: np.ndarray | None, what: str) -> None:
    """Times in the documented range (``|t| < 2**61 µs``) and strictly increasing; names
    the first offending line (or index)."""
    out = np.flatnonzero(np.abs(times) >= MAX_TIME_US * 1e-6)
    if out.size:
        i = int(out[0])
        where = int(lines[i]) if lines is not None else None
        index = "" if lines is not None else f"{what} {i}: "
        raise DataError(located(source, where, f"{index}t = {times[i]:.9g} s is out of range (|t| < 2**61 µs)"))
    back = np.flatnonzero(np.diff(times) <= 0)
    if back.size:
        i = int(back[0]) + 1
        where = int(lines[i]) if lines is not None else None
        index = "" if lines is not None else f"{what} {i}: "
        raise DataError(located(source, where, f"{index}timestamps must be strictly increasing, "
                                               f"got t = {times[i]:.9g} s after t = {times[i - 1]:.9g} s"))


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` from unit quaternions ``(n, 4)`` ordered ``qx qy qz qw``."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((q.shape[0], 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def slerp(q0: np.ndarray, q1: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Spherical interpolation between unit quaternions (rows), ``alpha`` in [0, 1]."""
    q1 = q1.copy()
    dot = np.sum(q0 * q1, axis=1)
    # q and -q are the same rotation; take the short way round.
    q1[dot < 0] *= -1
    dot = np.abs(dot)
    angle = np.arccos(np.clip(dot, -1.0, 1.0))
    a = alpha[:, None]
    out = (1 - a) * q0 + a * q1
    wide = angle > _SLERP_MIN_ANGLE
    if np.any(wide):
        s = np.sin(angle[wide])[:, None]
        aw = a[wide]
        out[wide] = (np.sin((1 - aw) * angle[wide, None]) * q0[wide] + np.sin(aw * angle[wide, None]) * q1[wide]) / s
    return out / np.linalg.norm(out, axis=1, keepdims=True)


class Trajectory:
    """Camera poses in the world, interpolated in time; a ``VelocitySource``.

    Parameters
    ----------
    times : (n,) seconds, strictly increasing, n >= 2.
    positions : (n, 3) camera centre in the world, metres.
    quaternions : (n, 4) ``qx qy qz qw``, the camera-to-world rotation ``R_wc``
        (normalised here).
    source : where the poses came from, for error messages.
    lines : line number of each pose in ``source`` (errors name lines, not indices).
    """

    def __init__(self, times, positions, quaternions, source: object = "<memory>",
                 lines: np.ndarray | None = None):
        times = np.asarray(times, dtype=np.float64)
        positions = np.asarray(positions, dtype=np.float64)
        quaternions = np.asarray(quaternions, dtype=np.float64)
        n = times.shape[0] if times.ndim == 1 else -1
        if times.ndim != 1 or positions.shape != (n, 3) or quaternions.shape != (n, 4):
            raise DataError(located(source, None, f"poses need times (n,), positions (n, 3) and quaternions (n, 4); "
                                                  f"got {times.shape}, {positions.shape}, {quaternions.shape}"))
        if n < 2:
            raise DataError(located(source, None, f"need at least 2 poses to derive a velocity, got {n}"))
        bad = ~(np.isfinite(times) & np.all(np.isfinite(positions), axis=1) & np.all(np.isfinite(quaternions), axis=1))
        # Scaled by the largest component first, so that neither 1e200 overflows nor
        # 1e-200 underflows: only a (near) zero quaternion has no rotation.
        scale = np.max(np.abs(quaternions), axis=1) if n else np.zeros(0)
        unit = quaternions / np.where(scale > 0, scale, 1.0)[:, None]
        norms = np.linalg.norm(unit, axis=1)
        with np.errstate(over="ignore", under="ignore"):
            zero = ~bad & ((scale == 0) | (scale * norms < 1e-12))
        for i, problem in ((_first(bad), "pose is not finite (NaN or inf)"),
                           (_first(zero), "quaternion qx qy qz qw is zero")):
            if i is not None:
                raise DataError(self._where(source, lines, i, problem))
        _check_times(times, source, lines, "pose")
        with np.errstate(over="ignore", invalid="ignore"):
            speeds = np.diff(positions, axis=0) / np.diff(times)[:, None]
        fast = _first(~np.all(np.isfinite(speeds), axis=1))
        if fast is not None:
            raise DataError(self._where(source, lines, fast + 1, "the velocity to this pose overflows (positions too "
                                                                 "far apart for the time between the poses)"))
        self.times = times
        self.positions = positions
        self.quaternions = unit / norms[:, None]
        self.source = source

    @staticmethod
    def _where(source: object, lines: np.ndarray | None, i: int, problem: str) -> str:
        where = int(lines[i]) if lines is not None else None
        return located(source, where, problem if lines is not None else f"pose {i}: {problem}")

    def __len__(self) -> int:
        return self.times.shape[0]

    def _segment(self, t: np.ndarray) -> np.ndarray:
        # The pose segment [t_i, t_i+1) holding t, clamped to the first/last segment.
        i = np.searchsorted(self.times, t, side="right") - 1
        return np.clip(i, 0, len(self) - 2)

    def _segment_velocity(self, i: np.ndarray) -> np.ndarray:
        dt = self.times[i + 1] - self.times[i]
        return (self.positions[i + 1] - self.positions[i]) / dt[:, None]

    def _rotation(self, t: np.ndarray, i: np.ndarray) -> np.ndarray:
        alpha = (t - self.times[i]) / (self.times[i + 1] - self.times[i])
        # Orientation is held at the end poses outside the recorded range.
        alpha = np.clip(alpha, 0.0, 1.0)
        return quaternion_to_matrix(slerp(self.quaternions[i], self.quaternions[i + 1], alpha))

    def velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Camera-frame velocity ``R_wc(t)^T dp/dt`` (m/s, shape ``(n, 3)``) at times ``t`` (s).

        ``dp/dt`` is the velocity of the pose segment holding ``t`` (constant over a
        segment); outside the recorded range the first/last segment's.
        """
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        i = self._segment(t)
        rotation = self._rotation(t, i)
        return np.einsum("nji,nj->ni", rotation, self._segment_velocity(i))

    def pose_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interpolated poses at times ``t`` (s): positions ``(n, 3)`` m and ``R_wc`` ``(n, 3, 3)``.

        Positions are linear in time within a segment and extrapolated along the
        first/last segment outside the range (consistent with ``velocity_at``);
        rotations are slerped and held at the end poses outside the range.
        """
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        i = self._segment(t)
        positions = self.positions[i] + self._segment_velocity(i) * (t - self.times[i])[:, None]
        return positions, self._rotation(t, i)


def _first(mask: np.ndarray) -> int | None:
    hits = np.flatnonzero(mask)
    return int(hits[0]) if hits.size else None


def read_groundtruth(path: str | Path) -> Trajectory:
    """Read ECD ``groundtruth.txt``: ``t px py pz qx qy qz qw`` per line (s, m, ``R_wc``)."""
    values, lines = read_table(path, ("t", "px", "py", "pz", "qx", "qy", "qz", "qw"), "pose")
    return Trajectory(values[:, 0], values[:, 1:4], values[:, 4:8], source=Path(path), lines=lines)


def write_groundtruth(path: str | Path, times, positions, quaternions) -> None:
    """Write poses as ECD ``groundtruth.txt`` (s, m, ``qx qy qz qw``), exactly round-tripping floats."""
    trajectory = Trajectory(times, positions, quaternions, source=Path(path))
    rows = np.column_stack([trajectory.times, trajectory.positions, np.asarray(quaternions, dtype=np.float64)])
    _write_rows(path, rows, "# timestamp px py pz qx qy qz qw  (s, m, camera-to-world)")


def _write_rows(path: str | Path, rows: np.ndarray, header: str) -> None:
    # repr() is the shortest text that reads back to the same float.
    text = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows)
    files.write_text_atomic(path, header + "\n" + text)


class VelocitySamples:
    """Camera-frame velocity samples, linearly interpolated and clamped; a ``VelocitySource``.

    Parameters
    ----------
    times : (n,) seconds, strictly increasing, n >= 1.
    velocities : (n, 3) m/s in the camera frame.
    """

    def __init__(self, times, velocities, source: object = "<memory>", lines: np.ndarray | None = None):
        times = np.asarray(times, dtype=np.float64)
        velocities = np.asarray(velocities, dtype=np.float64)
        if times.ndim != 1 or velocities.shape != (times.shape[0], 3):
            raise DataError(located(source, None, f"velocity samples need times (n,) and velocities (n, 3); "
                                                  f"got {times.shape} and {velocities.shape}"))
        if times.shape[0] == 0:
            raise DataError(located(source, None, "no velocity samples (expected lines 't vx vy vz')"))
        bad = _first(~(np.isfinite(times) & np.all(np.isfinite(velocities), axis=1)))
        if bad is not None:
            where = int(lines[bad]) if lines is not None else None
            raise DataError(located(source, where, "velocity sample is not finite (NaN or inf)"))
        _check_times(times, source, lines, "sample")
        self.times = times
        self.velocities = velocities
        self.source = source

    def velocity_at(self, t: np.ndarray) -> np.ndarray:
        """Velocity (m/s, camera frame, ``(n, 3)``) at times ``t`` (s); end values outside the range."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return np.column_stack([np.interp(t, self.times, self.velocities[:, k]) for k in range(3)])


def read_velocity_samples(path: str | Path) -> VelocitySamples:
    """Read ``t vx vy vz`` lines (s, m/s in the camera frame)."""
    values, lines = read_table(path, ("t", "vx", "vy", "vz"), "velocity sample")
    return VelocitySamples(values[:, 0], values[:, 1:4], source=Path(path), lines=lines)


def write_velocity_samples(path: str | Path, times, velocities) -> None:
    """Write ``t vx vy vz`` lines (s, m/s in the camera frame)."""
    samples = VelocitySamples(times, velocities, source=Path(path))
    _write_rows(path, np.column_stack([samples.times, samples.velocities]), "# t vx vy vz  (s, m/s, camera frame)")
