"""The time-surface estimator's rows fit, on points made by hand (``tofnet.kernels.time_surface_fit``)."""

import numpy as np
import pytest

from tofnet.kernels.time_surface_fit import FIT_ILL_CONDITIONED, FIT_OK, L_M, L_SS, L_ST, L_S, L_T, L_W, N_L, fit_rows

RADIUS = 5
LINES = 4 * RADIUS + 3  # as the estimator's table: line 0 is never used
MIDDLE = (LINES - 1) // 2


def travel_points(seed, depth, instrument, timing_px_m, count=2000):
    """Points of an edge at ``depth`` m in travel coordinates (net position ``s`` px, travel ``t`` px·m) on
    nine lines of their own offsets, each first event late or early by a travel ``e`` (px·m): under a
    rotation that moves it to ``(s - r e, t + e)`` (``r`` = ``instrument``, 1/m)."""
    rng = np.random.default_rng(seed)
    lines = rng.integers(-4, 5, count)
    s = rng.uniform(-6.0, 0.0, count)
    t = rng.normal(0.0, 3.0, 9)[lines + 4] + depth * s
    e = rng.normal(0.0, timing_px_m, count)
    return s - instrument * e, t + e, (MIDDLE + lines).astype(np.int64)


def slope(s, t, g, instrument):
    table, used = np.zeros((LINES, N_L)), np.zeros(LINES, np.int64)
    code, tau_s, *_ = fit_rows(s.copy(), np.zeros_like(s), t.copy(), np.append(g, 0), len(s), 3, 0.01, 1e9, 0,
                               table, used, np.inf, False, instrument)
    assert code == FIT_OK and not table[:, [L_M, L_S, L_T, L_SS, L_ST, L_W]].any()  # its sums left empty
    return tau_s


@pytest.mark.parametrize("ratio", [0.5, 1.5])
def test_a_travel_fit_under_a_rotation_takes_the_slope_its_timing_errors_leave_alone(ratio):
    """The rotation's image motion ``r Z`` = 1.5 and 4.5 times the translation's: least squares of the travel
    on the net position is pulled low (both carry the timing error), the instrumental slope is not."""
    depth = 2.0
    r = ratio * 3 / depth
    ordinary, instrumental = [], []
    for seed in range(6):
        s, t, g = travel_points(seed, depth, r, timing_px_m=0.3 / r)  # the position off by 0.3 px rms
        ordinary.append(slope(s, t, g, 0.0) / depth - 1)
        instrumental.append(slope(s, t, g, r) / depth - 1)
    # least squares: (Z var s - r σ²) / (var s + r² σ²), 4.9 and 3.6 % low; the instrument's scatter grows
    # with 1 + r Z (the residuals' share of the timing error): 0.7 and 0.5 % per fit here
    assert np.mean(ordinary) < -0.025
    assert abs(np.mean(instrumental)) < 0.006 and np.std(instrumental) < 0.015


def test_without_a_rotation_the_rows_fit_is_least_squares():
    s, t, g = travel_points(0, 2.0, 0.0, 0.2)
    centred = [(s[g == k] - s[g == k].mean(), t[g == k] - t[g == k].mean()) for k in np.unique(g)]
    expected = sum((a * b).sum() for a, b in centred) / sum((a * a).sum() for a, _ in centred)
    assert slope(s, t, g, 0.0) == pytest.approx(expected, rel=1e-12)


def test_an_instrument_that_says_the_image_stands_still_is_ill_conditioned():
    """``r = -1 / Z``: the rotation cancels the translation's image motion, ``s + r t`` is constant."""
    s, t, g = travel_points(0, 2.0, 0.0, 0.0)
    table, used = np.zeros((LINES, N_L)), np.zeros(LINES, np.int64)
    for instrument, code in ((-0.5, FIT_ILL_CONDITIONED), (-0.6, FIT_ILL_CONDITIONED), (0.3, FIT_OK)):
        got = fit_rows(s.copy(), np.zeros_like(s), t.copy(), np.append(g, 0), len(s), 3, 0.01, 1e9, 0, table, used,
                       np.inf, False, instrument)
        assert got[0] == code, (instrument, got)
