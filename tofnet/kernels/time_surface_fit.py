"""The time-surface estimator's fits (numba; used by ``tofnet.kernels.time_surface``).

Both take points in the frame of the image motion (``s`` pixels along ``A t``, ``w``
across, ``t`` µs relative to the event), reject outliers one at a time and return
``(code, τ_s, τ_w, c, kept, rms_px)``: ``FIT_OK``, ``FIT_TOO_FEW`` or ``FIT_ILL_CONDITIONED``,
the slopes along and across the motion (µs/px), the offset at the event (µs), the points
kept (the first ``kept`` of the arrays, which the fits reorder) and their rms distance from
the fit in pixels.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

FIT_OK, FIT_TOO_FEW, FIT_ILL_CONDITIONED, FIT_OVER_RMS = range(4)
#: Least variance of ``w`` within the lines (px², per point) for ``fit_rows`` to fit ``β``: below it (rms 0.1 px) the
#: points are on their lines' centres and ``β`` would fit their noise (a rotation's small shift across the motion
#: made it take the depth's place: docs/time_surface.md, 7h).
MIN_W_SPREAD = 0.01
# Per line of a ``fit_rows`` fit: raw sums (count, s, t, s², s t, w), means of s, t and w, centred sums of s.
# (The sums of w², s w and w t are the fit's, over all points: a line's centred ones are those less its
# mean of w times its sums, so a point adds one sum of w to its line's row, not four.)
L_M, L_S, L_T, L_SS, L_ST, L_W, L_MEAN_S, L_MEAN_T, L_MEAN_W, L_CSS, L_CST, N_L = range(12)


@njit(cache=True)
def fit_plane(ps, pw, pt, n, min_points, min_spread, outlier_px, iterations):
    """Least-squares plane ``t = c + τ_s s + τ_w w`` through the first ``n`` points, robustly.

    ``ps`` pixels along the image motion, ``pw`` across it, ``pt`` µs (Benosman et al. 2014's
    local plane, in the motion's frame). While the farthest point is more than ``outlier_px``
    pixels from the plane (its time error over the gradient's magnitude), it is dropped (moved
    past the kept ones) and the plane refitted, at most ``iterations`` times: one at a time,
    since a first fit pulled by several outliers would make good points look bad too. Returns
    ``(code, τ_s, τ_w, c, kept, rms_px)``: ``FIT_OK`` when a plane stands (µs/px, µs; the
    first ``kept`` points are the ones it fits, ``rms_px`` their rms distance from it in
    pixels), else ``FIT_TOO_FEW`` or ``FIT_ILL_CONDITIONED`` (the variance of ``s`` that ``w``
    leaves unexplained is below ``min_spread`` px²: the points do not extend along the motion).
    """
    k = n
    ss = sw = st = sss = ssw = sww = sst = swt = 0.0
    for i in range(k):
        s, w, t = ps[i], pw[i], pt[i]
        ss += s
        sw += w
        st += t
        sss += s * s
        ssw += s * w
        sww += w * w
        sst += s * t
        swt += w * t
    tau_s = tau_w = c = rms_px = 0.0
    for _ in range(iterations + 1):
        if k < min_points:
            return FIT_TOO_FEW, tau_s, tau_w, c, k, rms_px
        ms, mw, mt = ss / k, sw / k, st / k
        css, csw, cww = sss / k - ms * ms, ssw / k - ms * mw, sww / k - mw * mw
        cst, cwt = sst / k - ms * mt, swt / k - mw * mt
        if cww > 1e-9:  # points across the motion too: the full plane
            spread = css - csw * csw / cww
            if spread < min_spread:
                return FIT_ILL_CONDITIONED, tau_s, tau_w, c, k, rms_px
            det = css * cww - csw * csw
            tau_s = (cst * cww - cwt * csw) / det
            tau_w = (cwt * css - cst * csw) / det
        else:  # one line along the motion: its slope, nothing across
            if css < min_spread:
                return FIT_ILL_CONDITIONED, tau_s, tau_w, c, k, rms_px
            tau_s, tau_w = cst / css, 0.0
        c = mt - tau_s * ms - tau_w * mw
        slope = math.sqrt(tau_s * tau_s + tau_w * tau_w)
        sq = 0.0
        worst, worst_r = 0, 0.0
        for i in range(k):
            r = abs(pt[i] - c - tau_s * ps[i] - tau_w * pw[i])
            sq += r * r
            if r > worst_r:
                worst, worst_r = i, r
        rms_px = math.sqrt(sq / k) / slope if slope > 0.0 else math.inf
        if worst_r <= outlier_px * slope:
            break
        s, w, t = ps[worst], pw[worst], pt[worst]
        k -= 1
        ps[worst], pw[worst], pt[worst] = ps[k], pw[k], pt[k]
        ps[k], pw[k], pt[k] = s, w, t
        ss -= s
        sw -= w
        st -= t
        sss -= s * s
        ssw -= s * w
        sww -= w * w
        sst -= s * t
        swt -= w * t
    # When the iterations run out with an outlier left, the last plane stands and the rms
    # check judges it.
    return FIT_OK, tau_s, tau_w, c, k, rms_px


@njit(cache=True, inline="always")
def _line_stats(lines, g):
    """Means and centred sums of line ``g`` from its raw sums (NaN means: fewer than 2 points).

    Selects, not a branch: whether a line has two points is a coin toss in noise."""
    m = lines[g, L_M]
    many = m >= 2.0
    inv = 1.0 / (m if many else 1.0)
    mean_s, mean_t, mean_w = lines[g, L_S] * inv, lines[g, L_T] * inv, lines[g, L_W] * inv
    css, cst = lines[g, L_SS] - lines[g, L_S] * mean_s, lines[g, L_ST] - lines[g, L_S] * mean_t
    lines[g, L_MEAN_S], lines[g, L_MEAN_T] = (mean_s if many else math.nan), (mean_t if many else math.nan)
    lines[g, L_MEAN_W] = mean_w
    lines[g, L_CSS], lines[g, L_CST] = (css if many else 0.0), (cst if many else 0.0)


@njit(cache=True, inline="always")
def _add_point(lines, used, n_used, g, s, t):
    """Add a point (``s``, ``t``) to line ``g``'s raw sums, ``g`` to ``used`` if it is the line's first; the
    lines used so far."""
    used[n_used] = g
    n_used += np.int64(lines[g, L_M] == 0.0)  # lines in the order of their first point
    lines[g, L_M] += 1.0
    lines[g, L_S] += s
    lines[g, L_T] += t
    lines[g, L_SS] += s * s
    lines[g, L_ST] += s * t
    return n_used


@njit(cache=True, inline="always")
def _fits_beta(sww, det, kept, min_spread):
    """Whether the lines' ``w`` spread (by ``MIN_W_SPREAD`` px² per point, not rounding's) and leave ``s`` a spread
    net of ``w`` (``det / sww >= min_spread`` per point): then ``β`` is fitted beside the slope."""
    return (sww > MIN_W_SPREAD * kept) & (det > min_spread * kept * sww)


@njit(cache=True, inline="always")
def _rms(sq, kept, slope):
    """rms distance (px) of ``kept`` points with sum of squared time residuals ``sq`` (µs²) from a slope (µs/px)."""
    return math.sqrt(sq / kept) / slope if slope > 0.0 else math.inf


@njit(cache=True, _nrt=False)  # no reference counts of its arrays (two atomic operations each per fit)
def fit_rows(ps, pw, pt, pg, n, min_points, min_spread, outlier_px, iterations, lines, used, give_up_rms=math.inf,
             across=True, instrument=0.0):
    """Time per pixel along the image motion from lines of pixels parallel to it, robustly.

    Fits ``t = c_line + τ_s s + β w``: each line (``pg``: index of the point's line across the
    motion, the event's is ``middle``) gets its own offset and the slopes are shared, since
    pixels on one line see the same signal delayed while different lines fire at unrelated
    phases (docs/time_surface.md, "1. Method", step 3). A line is the pixels whose ``w`` (``pw``,
    px across the motion) rounds to it: unless the motion is along an axis they lie up to half a
    pixel either side of it, and an edge oblique to the motion reaches them earlier or later by
    that much times its slant: ``β`` (µs per px across, within the lines) takes it out where the
    lines' ``w`` leave ``s`` a spread of at least ``min_spread`` (section 7d). Outliers go one at
    a time as in ``fit_plane``. ``lines`` (``N_L`` columns, zero on entry and on return; its
    line 0 must be one no point is on, as with the estimator's ``4 radius + 3`` lines),
    ``used`` and ``pg`` past the points kept are scratch. Returns ``(code, τ_s, τ_w, c, kept,
    rms_px)`` like ``fit_plane``: ``kept`` counts the points on lines of two or more, the
    spread is their variance along ``s`` within their lines, ``τ_w`` the slope of the lines'
    offsets across the motion and ``c`` the offset of the event's line. A last pass above
    ``give_up_rms`` px rms returns ``FIT_OVER_RMS`` at once (with its ``τ_s`` and rms). ``across``
    False: no ``β`` (``pw`` is not read; the caller knows a line's ``w`` is one, or the lines are not
    the edges' tracks). ``instrument`` ``r`` (1/m; 0: ordinary least squares): for travel fits under a
    rotation, the rotation's image motion along the motion over the translation's (px/s over px·m/s).
    A point's timing error then moves its net position ``s`` and its travel ``t`` together, along
    ``(−r, 1)``, and least squares of ``t`` on ``s`` would be pulled low; the slope is taken with
    ``s + r t``, which that error leaves alone, as the instrument (docs/time_surface.md, 7i): the
    outliers are the least-squares fit's, the slope is the instrument's on the points kept.
    """
    middle = (lines.shape[0] - 1) // 2
    n_used = 0
    # each point added to its line's sums in memory, in order (no branch on where a run of one line ends:
    # in noise the runs are as long as chance makes them); at most 2 round(radius √2) + 1 lines are used.
    # Line indices are read as unsigned: numba fixes up every signed index for negative values.
    qww = qsw = qwt = 0.0  # the sums of w², s w, w t over the points
    if across:  # one pass over the points with the sums of w; without them the fit costs what it did before β
        for i in range(n):
            g = np.uint64(pg[i])
            s, w, t = ps[i], pw[i], pt[i]
            n_used = _add_point(lines, used, n_used, g, s, t)
            lines[g, L_W] += w
            qww += w * w
            qsw += s * w
            qwt += w * t
    else:
        for i in range(n):
            n_used = _add_point(lines, used, n_used, np.uint64(pg[i]), ps[i], pt[i])
    sxx = sxy = 0.0
    tww = tsw = twt = 0.0  # the lines' means of w times their sums of w, s, t: q less these are the centred sums
    kept = 0
    for j in range(n_used):
        g = np.uint64(used[j])
        _line_stats(lines, g)
        sxx += lines[g, L_CSS]
        sxy += lines[g, L_CST]
        kept += np.int64(lines[g, L_M]) if lines[g, L_M] >= 2.0 else 0
    if across:
        for j in range(n_used):
            g = np.uint64(used[j])
            tww += lines[g, L_W] * lines[g, L_MEAN_W]
            tsw += lines[g, L_S] * lines[g, L_MEAN_W]
            twt += lines[g, L_T] * lines[g, L_MEAN_W]
    k = n
    # Line 0 is never used (|w| <= radius √2 < middle): with a NaN mean it makes a point at index k that
    # pads a pass to an even count, which spares a mispredicted branch on the parity per pass.
    lines[0, L_MEAN_T] = math.nan
    tau_s = tau_w = c = 0.0
    # the last pass's sum of squares, points and |τ_s|: its rms, a root and a division, is taken once at the end
    # (off the passes' critical path); no pass yet: 0
    pass_sq, pass_kept, slope = 0.0, 1, -1.0
    code = FIT_OK
    for iteration in range(iterations + 1):
        if kept < min_points:
            code = FIT_TOO_FEW
            break
        if sxx < min_spread * kept:
            code = FIT_ILL_CONDITIONED
            break
        # β where the lines' w spread (not rounding's: motion along an axis) and s keeps a spread net of w
        # (det / sww >= min_spread kept), else the slope along s alone
        slant = False
        if across:
            sww, ssw, swy = qww - tww, qsw - tsw, qwt - twt
            det = sxx * sww - ssw * ssw
            slant = _fits_beta(sww, det, kept, min_spread)
        if slant:
            tau_s, beta = (sxy * sww - swy * ssw) / det, (swy * sxx - sxy * ssw) / det
        else:
            tau_s, beta = sxy / sxx, 0.0
        sq = 0.0
        worst, worst_r = 0, 0.0
        pg[np.uint64(k)] = 0  # the padding point (its residual is NaN: not the worst, not summed)
        if slant:
            for i in range(k + (k & 1)):
                g = np.uint64(pg[i])
                r = abs(pt[i] - lines[g, L_MEAN_T] - tau_s * (ps[i] - lines[g, L_MEAN_S])
                        - beta * (pw[i] - lines[g, L_MEAN_W]))
                if r > worst_r:  # False for NaN: a line of one point carries no slope
                    worst, worst_r = i, r
                sq += r * r if r == r else 0.0  # a select, not a branch, on the sum's dependency chain
        else:
            for i in range(k + (k & 1)):
                g = np.uint64(pg[i])
                r = abs(pt[i] - lines[g, L_MEAN_T] - tau_s * (ps[i] - lines[g, L_MEAN_S]))
                if r > worst_r:
                    worst, worst_r = i, r
                sq += r * r if r == r else 0.0
        slope, pass_sq, pass_kept = abs(tau_s), sq, kept
        if worst_r <= outlier_px * slope:
            break
        if iteration == iterations and _rms(pass_sq, pass_kept, slope) > give_up_rms:
            code = FIT_OVER_RMS  # its last removal and offsets would go unused
            break
        s, w, t, g = ps[worst], pw[worst], pt[worst], np.uint64(pg[worst])
        sxx -= lines[g, L_CSS]
        sxy -= lines[g, L_CST]
        if across:
            tww -= lines[g, L_W] * lines[g, L_MEAN_W]
            tsw -= lines[g, L_S] * lines[g, L_MEAN_W]
            twt -= lines[g, L_T] * lines[g, L_MEAN_W]
        kept -= np.int64(lines[g, L_M]) if lines[g, L_M] >= 2.0 else 0
        lines[g, L_M] -= 1.0
        lines[g, L_S] -= s
        lines[g, L_T] -= t
        lines[g, L_SS] -= s * s
        lines[g, L_ST] -= s * t
        if across:
            lines[g, L_W] -= w
            qww -= w * w
            qsw -= s * w
            qwt -= w * t
        _line_stats(lines, g)
        sxx += lines[g, L_CSS]
        sxy += lines[g, L_CST]
        if across:
            tww += lines[g, L_W] * lines[g, L_MEAN_W]
            tsw += lines[g, L_S] * lines[g, L_MEAN_W]
            twt += lines[g, L_T] * lines[g, L_MEAN_W]
        kept += np.int64(lines[g, L_M]) if lines[g, L_M] >= 2.0 else 0
        k -= 1
        last = np.uint64(k)  # >= 0 (a point was the worst): unsigned spares the negative-index fix-ups
        ps[worst], pw[worst], pt[worst], pg[worst] = ps[last], pw[last], pt[last], pg[last]
        ps[last], pw[last], pt[last], pg[last] = s, w, t, np.int64(g)
    if code == FIT_OK and instrument != 0.0:  # Σ u t / Σ u s with u = s + r t, within the lines (and β's w)
        syy = 0.0
        for i in range(k):
            d = pt[i] - lines[np.uint64(pg[i]), L_MEAN_T]
            syy += d * d if d == d else 0.0
        ux, uy = sxx + instrument * sxy, sxy + instrument * syy
        sww = ssw = swy = 0.0
        if across:
            sww, ssw, swy = qww - tww, qsw - tsw, qwt - twt
        uw = ssw + instrument * swy
        det = ux * sww - uw * ssw
        if across and _fits_beta(sww, sxx * sww - ssw * ssw, kept, min_spread):
            tau_s = (uy * sww - uw * swy) / det
        else:
            tau_s = uy / ux
        # Σ u s = (1 + r Z) Σ s², 1 + r Z the image motion over the translation's: the image must move along f
        if not (ux > 1e-6 * sxx and abs(tau_s) < math.inf):
            code = FIT_ILL_CONDITIONED
    if code == FIT_OK:
        # The lines' offsets against their position across the motion: τ_w (weighted by points).
        sw = so = sww = swo = total = 0.0
        for j in range(n_used):
            g = np.uint64(used[j])
            m = lines[g, L_M]
            if m >= 1.0:
                w, offset = float(np.int64(g) - middle), (lines[g, L_T] - tau_s * lines[g, L_S]) / m
                total += m
                sw += m * w
                so += m * offset
                sww += m * w * w
                swo += m * w * offset
        spread_w = sww - sw * sw / total
        tau_w = (swo - sw * so / total) / spread_w if spread_w > 0.0 else 0.0
        if lines[middle, L_M] > 0.0:
            c = (lines[middle, L_T] - tau_s * lines[middle, L_S]) / lines[middle, L_M]
        else:
            c = so / total - tau_w * sw / total
    for j in range(n_used):  # leave the table empty for the next fit
        g = np.uint64(used[j])
        lines[g, L_M] = lines[g, L_S] = lines[g, L_T] = lines[g, L_SS] = lines[g, L_ST] = 0.0
        lines[g, L_W] = 0.0
    lines[0, L_MEAN_T] = 0.0
    return code, tau_s, tau_w, c, kept, _rms(pass_sq, pass_kept, slope) if slope >= 0.0 else 0.0
