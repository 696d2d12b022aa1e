"""Data behind the figures: time windows, accumulated depth images, 3D back-projection.

Kept apart from ``plots.py`` so each reduction is tested on numbers, not pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.errors import DataError, TofnetError
from tofnet.units import format_seconds, seconds


@dataclass(frozen=True)
class Window:
    """A time window ``[start_us, end_us)`` in the recording's clock (µs); ``t0_us`` names times."""

    start_us: int
    end_us: int
    t0_us: int
    whole: bool = False
    #: The default length (s) this window was widened from, because it held few estimates.
    widened_from_s: float | None = None

    @property
    def duration_s(self) -> float:
        return (self.end_us - self.start_us) * 1e-6

    def label(self) -> str:
        """``"70 ms, 1.465-1.535 s"`` (times since ``t0``) or ``"the whole run (4 s)"``."""
        a = (self.start_us - self.t0_us) * 1e-6
        b = (self.end_us - self.t0_us) * 1e-6
        return f"the whole run ({b:.2f} s)" if self.whole else f"{format_seconds(self.duration_s)}, {a:.3f}\u2013{b:.3f} s"

    def note(self) -> str:
        """A title's second line when the window was widened, else ``""``."""
        if self.widened_from_s is None:
            return ""
        return f"\n(widened from the default {format_seconds(self.widened_from_s)}, which held few estimates)"

    def contains(self, t_us: np.ndarray) -> np.ndarray:
        t_us = np.asarray(t_us)
        return (t_us >= self.start_us) & (t_us < self.end_us)


def time_span_us(events: np.ndarray, depth: np.ndarray, t0_us: int) -> tuple[int, int]:
    """``[t0, end)`` covering every event and estimate stamp (µs)."""
    ends = [t0_us + 1]
    if len(events):
        ends.append(int(events["t"].max()) + 1)
    if len(depth):
        ends.append(int(depth["t"].max()) + 1)
    return t0_us, max(ends)


def resolve_window(spec: str | float | None, span_us: tuple[int, int], *, default_s: float | None) -> Window:
    """The window a user asked for.

    ``spec`` is ``"START:END"`` (seconds since ``t0``, units allowed: ``"1.2:1.27"``,
    ``"1200ms:1270ms"``), a duration (``"70ms"``, ``0.07``: that long, centred in the
    span) or None (``default_s`` long and centred; the whole span when None).
    """
    t0, end = span_us
    if spec is None or spec == "":
        if default_s is None:
            return Window(t0, end, t0, whole=True)
        spec = default_s
    if isinstance(spec, str) and ":" in spec:
        first, _, second = spec.partition(":")
        a = seconds(first, "window start") if first.strip() else 0.0
        b = seconds(second, "window end") if second.strip() else (end - t0) * 1e-6
        if not b > a:
            raise TofnetError(f"window {spec!r}: the end must come after the start")
        if a * 1e6 >= end - t0 or b <= 0:  # nothing of the recording or the run: an empty figure says nothing
            raise TofnetError(f"window {spec!r}: outside the span of the events and estimates, 0 .. "
                              f"{(end - t0) * 1e-6:g} s since its start")
        return Window(t0 + int(round(a * 1e6)), t0 + int(round(b * 1e6)), t0)
    length = seconds(spec, "window")
    if not length > 0:
        raise TofnetError(f"window {spec!r}: expected a positive duration like '70ms' or START:END")
    length_us = int(round(length * 1e6))
    if length_us >= end - t0:
        return Window(t0, end, t0, whole=True)
    start = t0 + (end - t0 - length_us) // 2
    return Window(start, start + length_us, t0)


def widened_window(window: Window, span_us: tuple[int, int], stamps_us: np.ndarray, enough: int) -> Window:
    """``window`` (a default one), doubled about its centre until it holds ``enough`` of ``stamps_us`` or
    the whole span: a sparse run's 70 ms held one estimate of a thousand (a black image)."""
    start, end = window.start_us, window.end_us
    t0, stop = span_us
    if window.whole or np.count_nonzero((stamps_us >= start) & (stamps_us < end)) >= enough:
        return window
    length = end - start
    while True:
        length *= 2
        if length >= stop - t0:
            return Window(t0, stop, window.t0_us, whole=True, widened_from_s=window.duration_s)
        centre = (start + end) // 2
        a = min(max(t0, centre - length // 2), stop - length)
        if np.count_nonzero((stamps_us >= a) & (stamps_us < a + length)) >= enough:
            return Window(a, a + length, window.t0_us, widened_from_s=window.duration_s)


def sensor_size_of(recording, depth: np.ndarray) -> tuple[int, int]:
    """``(width, height)`` from the recording, else from the largest pixel seen."""
    if recording.sensor_size is not None:
        return int(recording.sensor_size[0]), int(recording.sensor_size[1])
    xs = [int(a["x"].max()) for a in (recording.events, depth) if len(a)]
    ys = [int(a["y"].max()) for a in (recording.events, depth) if len(a)]
    return (max(xs) + 1, max(ys) + 1) if xs else (1, 1)


def depth_image(x: np.ndarray, y: np.ndarray, z: np.ndarray, t: np.ndarray, size: tuple[int, int],
                reduce: str = "latest") -> np.ndarray:
    """Accumulate depths (m) per pixel into a ``(height, width)`` image, NaN where none.

    ``reduce`` is ``"latest"`` (the depth with the largest ``t``; ties: the later
    entry) or ``"median"`` (of all depths of the pixel).
    """
    width, height = size
    image = np.full((height, width), np.nan)
    inside = (x < width) & (y < height)
    x, y, z, t = (np.asarray(a)[inside] for a in (x, y, z, t))
    if len(z) == 0:
        return image
    pixel = y.astype(np.int64) * width + x.astype(np.int64)
    if reduce == "latest":
        order = np.lexsort((np.arange(len(z)), t, pixel))  # per pixel by time, last = latest
        last = np.r_[pixel[order][1:] != pixel[order][:-1], True]
        image.flat[pixel[order][last]] = z[order][last]
    elif reduce == "median":
        order = np.lexsort((z, pixel))
        p_sorted, z_sorted = pixel[order], z[order]
        starts = np.flatnonzero(np.r_[True, p_sorted[1:] != p_sorted[:-1]])
        counts = np.diff(np.r_[starts, len(p_sorted)])
        # The median of a sorted run is the mean of its one or two middle entries.
        image.flat[p_sorted[starts]] = 0.5 * (z_sorted[starts + (counts - 1) // 2] + z_sorted[starts + counts // 2])
    else:
        raise TofnetError(f"depth map reduce must be 'latest' or 'median', got {reduce!r}")
    return image


def depth_range(*arrays: np.ndarray, low: float = 2.0, high: float = 98.0) -> tuple[float, float]:
    """Colour range (m) from percentiles of the finite values, so outliers do not wash it out."""
    values = np.concatenate([np.asarray(a, dtype=np.float64).ravel() for a in arrays] or [np.empty(0)])
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return 0.0, 1.0
    lo, hi = np.percentile(values, [low, high])
    if hi - lo < 1e-6:
        lo, hi = lo - 0.5, hi + 0.5
    return float(lo), float(hi)


def back_project(x: np.ndarray, y: np.ndarray, z: np.ndarray, intrinsics) -> np.ndarray:
    """Camera-frame points ``(n, 3)`` m: ``X = (x - cx) / fx * z``, ``Y = (y - cy) / fy * z``, ``Z = z``."""
    z = np.asarray(z, dtype=np.float64)
    return np.column_stack([(np.asarray(x, dtype=np.float64) - intrinsics.cx) / intrinsics.fx * z,
                            (np.asarray(y, dtype=np.float64) - intrinsics.cy) / intrinsics.fy * z, z])


def to_world(points_cam: np.ndarray, positions: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """World points ``R_wc @ p + c`` for per-point camera centres ``(n, 3)`` and ``R_wc`` ``(n, 3, 3)``."""
    return np.einsum("nij,nj->ni", rotations, points_cam) + positions


def has_poses(trajectory) -> bool:
    """True when ``poses_at`` can place the camera: ``pose_at`` or ``position_at``."""
    return trajectory is not None and any(callable(getattr(trajectory, name, None))
                                          for name in ("pose_at", "position_at"))


def poses_at(trajectory, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres ``(n, 3)`` m and ``R_wc`` ``(n, 3, 3)`` at times ``t_s`` (s).

    Uses ``pose_at`` (ground-truth poses); a trajectory with only ``position_at`` (the
    simulator's, whose camera never turns: camera = world axes) gets identity rotations.
    """
    t_s = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    if callable(getattr(trajectory, "pose_at", None)):
        return trajectory.pose_at(t_s)
    if callable(getattr(trajectory, "position_at", None)):
        return trajectory.position_at(t_s), np.broadcast_to(np.eye(3), (len(t_s), 3, 3)).copy()
    raise DataError("the camera trajectory has no poses (groundtruth.txt), only velocities")


def event_times_us(depth: np.ndarray, meta: dict) -> np.ndarray:
    """Middle of the input step that triggered each estimate (µs): when the edge was seen."""
    step = depth["step"].astype(np.int64) - int(meta["latency_steps"])
    return int(meta["t0_us"]) + step * int(meta["timestep_us"]) + int(meta["timestep_us"]) // 2


def world_points(depth: np.ndarray, intrinsics, trajectory, t_us: np.ndarray | None = None) -> np.ndarray:
    """Estimates as world points (m), each placed with the camera pose at ``t_us``.

    ``t_us`` defaults to the estimates' stamps; ``event_times_us`` gives the time the
    depth refers to (2-3 steps earlier), the better choice when the metadata is known.
    """
    if intrinsics is None:
        raise DataError("the 3D view needs the camera intrinsics (calib.txt) to back-project pixels")
    if not has_poses(trajectory):
        raise DataError("the 3D view needs camera poses (groundtruth.txt) to place points in the world")
    cam = back_project(depth["x"], depth["y"], depth["z"], intrinsics)
    t = depth["t"] if t_us is None else np.asarray(t_us)
    positions, rotations = poses_at(trajectory, t * 1e-6)
    return to_world(cam, positions, rotations)
