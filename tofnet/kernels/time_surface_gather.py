"""Where the time-surface fit's points come from (numba; used by ``tofnet.kernels.time_surface``).

The pixels just behind an event along the image motion, the window in time, and the gather of
the recent first events of the square the edge has crossed (docs/time_surface.md, section 1).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tofnet.kernels.time_surface_fit import fit_plane


@njit(cache=True, inline="always")
def behind_steps(a: float, speed2: float) -> tuple[int, int]:
    """``floor(f + 0.5)`` and ``floor(2 f + 0.5)`` of the unit motion's component ``f = a / √speed2``
    (``|f| <= 1``), from squares and without branches: the steps (px) to the pixels 1 and 2 px
    behind along one axis (a tie rounds up, as ``floor``)."""
    a2 = a * a
    quarter, half, three = 0.0625 * speed2, 0.25 * speed2, 0.5625 * speed2  # |f| = 1/4, 1/2, 3/4
    up_one, up_two = np.int64(a2 >= half), np.int64(a2 >= quarter) + np.int64(a2 >= three)
    down_one, down_two = np.int64(a2 > half), np.int64(a2 > quarter) + np.int64(a2 > three)
    positive = a > 0.0
    return (up_one if positive else -down_one), (up_two if positive else -down_two)


@njit(cache=True, inline="always")
def gather(surface, cell: int, row: int, radius: int, t: int, window: int, fu: float, fv: float, ahead_px: float,
           middle: int, ps_, pw, pt, pg) -> int:
    """Step 2: the first events no older than ``window`` µs at the pixels of the square around
    ``surface[cell]`` (the flat surface, ``cell`` in the event's polarity's plane) that the edge
    has crossed (at most ``ahead_px`` ahead along the motion ``(fu, fv)``; the event itself
    always counts), in row order, as points: ``s`` px along the motion, ``w`` px across it,
    ``t`` µs (before the event: negative) and the index of their line across the motion (the
    event's: ``middle``). Returns their count.

    Branch-free over the cells: each is written and the count advanced by its age test (on
    noise that test is a coin toss for a branch predictor). The indices are unsigned, which
    spares numba's negative-index fix-ups: every cell is inside the bordered plane and every
    point inside the scratch arrays."""
    inverse_fu = 1.0 / fu if abs(fu) > 1e-9 else 0.0
    n = 0
    for dv in range(-radius, radius + 1):
        lo, hi = -radius, radius  # the columns with du * fu + dv * fv <= ahead_px
        limit = ahead_px - dv * fv
        if fu > 1e-9:
            hi = min(hi, np.int64(math.floor(limit * inverse_fu)))
        elif fu < -1e-9:
            lo = max(lo, np.int64(math.ceil(limit * inverse_fu)))
        elif limit < 0.0:
            hi = lo - 1
        base = cell + dv * row
        along0, across0 = dv * fv, dv * fu
        for du in range(lo, hi + 1):
            age = t - surface[np.uint64(base + du)]
            across = across0 - du * fv
            at = np.uint64(n)
            ps_[at], pw[at], pt[at] = along0 + du * fu, across, -age
            pg[at] = middle + np.int64(math.floor(across + 0.5))
            n += np.int64(age <= window)
        if dv == 0 and not lo <= 0 <= hi:  # the event itself always counts
            at = np.uint64(n)
            ps_[at], pw[at], pt[at], pg[at] = 0.0, 0.0, 0.0, middle
            n += 1
    return n


@njit(cache=True, inline="always")
def expand(ps_, pt, n: int, expansion: float) -> None:
    """Scale the first ``n`` points' times (µs before the event) by ``1 + e s`` (``s`` px along the motion,
    ``e = t_z / |A t|`` per px): under a translation the image at ``s`` moves ``1 + e s`` times as fast as
    at the event, so the scaled times are a line in ``s`` whose slope is the event's (docs/time_surface.md,
    7g). ``e = 0`` (no motion along the optical axis): nothing to do. Held at 1/4 within a few pixels of
    the focus of expansion."""
    if expansion != 0.0:
        for i in range(n):
            pt[i] = pt[i] * max(1.0 + expansion * ps_[i], 0.25)


@njit(cache=True, inline="always")
def time_window(window_us, window_depth, radius, speed, turn, t, since, window_px, du1, dv1, du2, dv2, fu, fv, age1,
                 age2):
    """Step 2's window in time (µs): the time a surface at ``window_depth`` takes to move ``radius`` px (at
    least ``window_us``), nothing from before the camera's last turn, nor more than ``window_px`` crossings
    at the edge's pace (the larger of the two pixels behind's ages per pixel)."""
    window = window_us
    if window_depth > 0.0:
        window = max(window, np.int64(math.floor(window_depth * radius / speed * 1e6)))
    if turn > 0.0:  # nothing from before the camera's last turn: another motion made it
        window = min(window, t - np.int64(since))
    if window_px > 0.0:  # window_px crossings at the edge's pace (µs), without a branch
        d1, d2 = du1 * fu + dv1 * fv, du2 * fu + dv2 * fv  # their distances behind along the motion, px
        local = window_px * max(age1 / d1, age2 / d2)
        window = np.int64(math.ceil(min(local, float(window))))
    return window


@njit(cache=True)
def trimmed_plane(ps_, pw, pt, window, trim_px, fit, tau_s, tau_w, c, kept, rms, min_points, min_spread, outlier_px,
             iterations):
    """The plane refitted without the points it puts within ``trim_px`` px of the window's ends.

    The window cuts on measured times: near its ends only the points that fired late (old end)
    or early (the present) are in, which flattens the plane; cutting on the fitted times is unbiased."""
    margin = trim_px * math.sqrt(tau_s * tau_s + tau_w * tau_w)
    m = 0
    for i in range(kept):
        fitted = c + tau_s * ps_[i] + tau_w * pw[i]
        if -window + margin <= fitted <= -margin:
            ps_[m], pw[m], pt[m] = ps_[i], pw[i], pt[i]
            m += 1
    if m < kept:
        return fit_plane(ps_, pw, pt, m, min_points, min_spread, outlier_px, iterations)
    return fit, tau_s, tau_w, c, kept, rms
