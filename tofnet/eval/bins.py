"""How the figures bin their data: depth histograms on the counter's steps, error-band
windows sized from the data, and a point cloud's estimates per ray.

Kept apart from the drawing so each rule is tested on numbers, not pixels.
"""

from __future__ import annotations

import numpy as np


def nice_step(span: float, target_bins: int, multipliers: tuple[float, ...] = (1, 2, 2.5, 5, 10)) -> float:
    """A round bin width (``multipliers`` times a power of ten) giving at most ``target_bins`` bins."""
    raw = max(span, 1e-9) / target_bins
    magnitude = 10.0 ** np.floor(np.log10(raw))
    return float(next(m * magnitude for m in multipliers if m * magnitude >= raw * (1 - 1e-9)))


def depth_lattice(z: np.ndarray, *, max_levels: int = 5000, tolerance: float = 0.01,
                  share: float = 0.99) -> float | None:
    """The depth step ``q`` (m) when the depths are whole multiples of one step, else None.

    The paper's network measures a time of travel as a whole number ``n`` of timesteps,
    so under a constant ``A t`` its depths are ``n * |A t| * dt``: one value per counter
    step and nothing between. ``q`` is fitted to the distinct values; it is returned when
    at least ``share`` of the depths lie within ``tolerance`` steps of a multiple and the
    values span at most ``max_levels`` steps (a continuous estimator's do not).
    """
    z = np.asarray(z, dtype=np.float64)
    z = z[np.isfinite(z) & (z > 0)]
    levels, counts = np.unique(z, return_counts=True)
    if len(levels) < 2 or len(levels) > max_levels:
        return None
    gaps = np.diff(levels)
    gaps = gaps[gaps > 1e-6 * levels[-1]]  # float rounding of one value is no step
    if len(gaps) == 0 or levels[-1] / gaps.min() > max_levels:
        return None
    n = np.maximum(np.round(levels / gaps.min()), 1.0)
    q = float(np.sum(levels * n) / np.sum(n * n))  # least squares over the distinct values
    on = np.abs(levels / q - np.round(levels / q)) <= tolerance
    return q if counts[on].sum() >= share * counts.sum() else None


def histogram_edges(values: np.ndarray, estimates: np.ndarray, target_bins: int = 100
                    ) -> tuple[np.ndarray, float | None, int]:
    """Bin edges (m) for a depth histogram of ``values`` (estimates and truths), from 0 to
    about the 99.5th percentile, and the estimates' step ``q`` and steps per bin ``k``.

    When the estimates lie on a lattice (``depth_lattice``) each bin holds exactly ``k``
    steps, edges half a step off the lattice (``(k j + 1/2) q``): a round width would
    hold one step in some bins and two in others, or none (empty bins). Otherwise the
    bins have a round width from 0 and ``q`` is None, ``k`` 0.
    """
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    top = max(float(np.percentile(values, 99.5)) * 1.05 if len(values) else 1.0, 1e-3)
    width = nice_step(top, target_bins)
    q = depth_lattice(estimates)
    if q is None:
        return np.arange(0.0, top + width, width), None, 0
    k = max(1, int(round(width / q)))
    bins = max(1, int(np.ceil((top / q - 0.5) / k)))
    return q * (0.5 + k * np.arange(bins + 1)), q, k


def band_window_s(matched: int, duration_s: float, timestep_s: float, *, per_window: int = 200,
                  most: int = 100) -> float:
    """Window (s) of an error band over ``duration_s``: a round number of timesteps (1, 2 or
    5 times a power of ten) long enough for about ``per_window`` matched estimates per
    window on average, but at most ``most`` windows and at least one timestep."""
    want = max(duration_s / most, duration_s * per_window / max(matched, 1), timestep_s)
    steps = nice_step(want / timestep_s, 1, (1, 2, 5, 10))
    return max(1, int(round(steps))) * timestep_s


def window_quartiles(t_rel_us: np.ndarray, values: np.ndarray, window_us: int, n_windows: int,
                     *, least: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """25th, 50th and 75th percentiles ``(3, n_windows)`` of ``values`` per window of
    ``window_us`` (by time since ``t0``, µs), NaN where a window holds fewer than ``least``;
    and the count per window."""
    win = np.asarray(t_rel_us, dtype=np.int64) // np.int64(window_us)
    keep = (win >= 0) & (win < n_windows)
    order = np.argsort(win[keep], kind="stable")
    w_sorted, v_sorted = win[keep][order], np.asarray(values)[keep][order]
    bounds = np.searchsorted(w_sorted, np.arange(n_windows + 1))
    counts = np.diff(bounds)
    q = np.full((3, n_windows), np.nan)
    for i in np.flatnonzero(counts >= max(least, 1)):  # one iteration per window, not per value
        q[:, i] = np.percentile(v_sorted[bounds[i]:bounds[i + 1]], [25, 50, 75])
    return q, counts


def ray_medians(points_cam: np.ndarray, angle: float, least: int = 3
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cloud binned along rays: camera-frame points (m) grouped by direction into
    cells ``angle`` (rad) wide in ``x/z`` and ``y/z``; per cell holding at least ``least``
    points, one point on the cell's central ray at the median depth of its points.

    Returns ``(points (m, 3), count, spread)`` per cell, ``spread`` the interquartile range
    of the cell's depths over their median (0: they agree). Estimates scattered along a ray
    by a timing error collapse onto the surface they measure; points behind the camera are
    left out.
    """
    p = np.asarray(points_cam, dtype=np.float64)
    p = p[p[:, 2] > 0]
    cell = np.floor(p[:, :2] / p[:, 2:3] / angle).astype(np.int64)
    cells, group, counts = np.unique(cell.reshape(-1, 2), axis=0, return_inverse=True, return_counts=True)
    z = p[np.lexsort((p[:, 2], group.ravel())), 2]  # grouped by cell, by depth within one
    starts = np.cumsum(counts) - counts
    keep = counts >= least
    cells, counts, starts = cells[keep], counts[keep], starts[keep]

    def quantile(share: float) -> np.ndarray:  # per cell, interpolated between ranks (as np.percentile)
        pos = share * (counts - 1)
        low = np.floor(pos).astype(np.int64)
        high = np.minimum(low + 1, counts - 1)
        return z[starts + low] + (pos - low) * (z[starts + high] - z[starts + low])

    median = quantile(0.5)
    spread = (quantile(0.75) - quantile(0.25)) / median
    rays = (cells + 0.5) * angle  # x/z, y/z of each cell's central ray
    return np.column_stack([rays * median[:, None], median]), counts, spread
