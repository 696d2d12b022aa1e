"""Depth from the local slope of the time surface (beyond the paper; DESIGN "Beyond the paper").

The numba core of the time-surface estimator; the streaming API and the parameters'
meaning are in ``tofnet.kernels.time_surface_estimator``, the method and the measurements
behind the defaults in docs/time_surface.md. Per pixel and polarity the state holds the
time (µs) of the last *first event* of an edge: the surface ``T(u, v)``. Per event:

1. first-event rule: an event of a pixel and polarity whose last first event is more
   recent than its hold (``hold_px`` times the time per pixel the last fit there
   measured, else the refractory period) is part of the same edge's burst: dropped;
2. gather the first events of the same polarity (or both) within ``radius`` pixels that
   the edge has already crossed (at most ``ahead_px`` along the image motion ``A t``), no
   older than the window nor than the camera's last turn;
3. fit ``t = a u + b v + c`` by least squares (µs, pixels), dropping the point farthest
   from the plane while it is more than ``outlier_px`` pixels away (along the gradient),
   at most ``iterations`` times; optionally drop the points the plane puts within
   ``trim_px`` pixels of the window's ends and refit; check points, spread and rms;
4. ``∇T = (a, b)`` s/px is the time of travel (DESIGN eq. 8: ``td = dT/du``, positive for
   motion towards +u): ``Z = (A t)·∇T``, or ``(A t)·∇T / (1 − (B ω)·∇T)`` with a rotation.

Every event ends in exactly one count slot (``COUNT_NAMES``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tofnet.kernels.velocity import velocity_term

NEVER = -(1 << 62)  # "no first event yet" (µs)

#: Count slots: where each event ended. Drops of events, rejections of estimates, emitted.
(OUT_OF_BOUNDS, BEFORE_T0, BURST, NO_MOTION, TOO_FEW_POINTS, ILL_CONDITIONED, BAD_FIT, ROTATION_DOMINATED,
 TOO_NEAR, TOO_FAR, INCONSISTENT, EMITTED, N_COUNTS) = range(13)
COUNT_NAMES = ("out_of_bounds", "before_t0", "burst", "no_motion", "too_few_points", "ill_conditioned",
               "bad_fit", "rotation_dominated", "too_near", "too_far", "inconsistent", "emitted")
DROP_SLOTS = (OUT_OF_BOUNDS, BEFORE_T0, BURST)  # not the first event of an edge
REJECT_SLOTS = tuple(range(NO_MOTION, EMITTED))  # a first event whose estimate was rejected

# Integer parameters (``ip``) and float parameters (``fp``), by slot.
(I_WIDTH, I_HEIGHT, I_RADIUS, I_T0, I_DT, I_LATENCY, I_UPDATE_EVERY, I_BOTH, I_MIN_POINTS, I_ITERATIONS,
 I_REFRACTORY, I_BURST_GAP, I_WINDOW, I_CONSISTENCY_WINDOW, I_MAX_HOLD, I_RECORD_REJECTED, I_MODEL, N_IP) = range(18)
(F_FX, F_FY, F_CX, F_CY, F_OUTLIER, F_MAX_RMS, F_MIN_SPREAD, F_MIN_DEPTH, F_MAX_DEPTH, F_MIN_DENOMINATOR,
 F_WINDOW_DEPTH, F_REFRACTORY_DEPTH, F_CONSISTENCY, F_HOLD_PX, F_AHEAD_PX, F_TURN, F_TRIM_PX, N_FP) = range(18)
# Motion state: the velocity the current epoch started with, its start (µs), the last update seen.
M_VX, M_VY, M_VZ, M_SINCE, M_UPDATE, N_MOTION = range(6)
# Fit models (``I_MODEL``): a plane, a surface curved across the motion, lines along the motion.
MODEL_PLANE, MODEL_CURVED, MODEL_ROWS = range(3)
MODELS = ("plane", "curved", "rows")
# Status of a call.
OK, UNSORTED, NO_VELOCITY = range(3)


@njit(cache=True)
def rotational_flow(wx: float, wy: float, wz: float, u: float, v: float,
                    fx: float, fy: float, cx: float, cy: float) -> tuple[float, float]:
    """``B ω`` in px/s at image point (u, v) for angular velocity (wx, wy, wz) rad/s (DESIGN, Rotation).

    The rotation issue (12) owns this formula; this copy serves the estimator's hook until
    that one is merged (then import it instead).
    """
    x, y = u - cx, v - cy
    return (x * y / fy * wx - (fx + x * x / fx) * wy + fx / fy * y * wz,
            (fy + y * y / fy) * wx - x * y / fx * wy - fy / fx * x * wz)


@njit(cache=True)
def follow_motion(motion, row, update: int, update_start_us: int, turn: float) -> None:
    """Start a new motion epoch at ``update`` when its velocity differs from the epoch's by more
    than ``turn`` times the epoch's speed (a turn, a start or a stop); ``turn = 0``: never."""
    dx, dy, dz = row[0] - motion[M_VX], row[1] - motion[M_VY], row[2] - motion[M_VZ]
    change = math.sqrt(dx * dx + dy * dy + dz * dz)
    speed = math.sqrt(motion[M_VX] ** 2 + motion[M_VY] ** 2 + motion[M_VZ] ** 2)
    if motion[M_UPDATE] < 0 or (turn > 0.0 and change > turn * speed):
        motion[M_VX], motion[M_VY], motion[M_VZ] = row[0], row[1], row[2]
        motion[M_SINCE] = update_start_us
    motion[M_UPDATE] = update


@njit(cache=True)
def _solve(k, sums, beta, ridge):
    """Least squares on the accumulated ``sums`` (``_accumulate``) of ``k`` points: the coefficients
    of ``t = b0 + b1 w + b2 w² + b3 s`` into ``beta``; returns the variance of ``s`` left after
    regressing it on (1, w, w²) (px², the spread that determines b3), or -1 when singular.

    ``ridge`` (times k) on the w and w² terms lets a row of points along s, or the plane model
    (w² terms all 0), solve with those coefficients near 0 instead of failing.
    """
    # Normal matrix (symmetric) and right-hand side, regressors ordered (1, w, w², s).
    n00, n01, n02, n03 = float(k), sums[0], sums[1], sums[2]
    n11, n12, n13 = sums[3] + ridge * k, sums[4], sums[5]
    n22, n23 = sums[6] + ridge * k, sums[7]
    n33 = sums[8]
    r0, r1, r2, r3 = sums[9], sums[10], sums[11], sums[12]
    # Cholesky N = L Lᵀ.
    l00 = math.sqrt(n00)
    l10, l20, l30 = n01 / l00, n02 / l00, n03 / l00
    d11 = n11 - l10 * l10
    if d11 <= 0.0:
        return -1.0
    l11 = math.sqrt(d11)
    l21, l31 = (n12 - l20 * l10) / l11, (n13 - l30 * l10) / l11
    d22 = n22 - l20 * l20 - l21 * l21
    if d22 <= 0.0:
        return -1.0
    l22 = math.sqrt(d22)
    l32 = (n23 - l30 * l20 - l31 * l21) / l22
    d33 = n33 - l30 * l30 - l31 * l31 - l32 * l32
    if d33 <= 0.0:
        return -1.0
    l33 = math.sqrt(d33)
    # L y = r, then Lᵀ beta = y.
    y0 = r0 / l00
    y1 = (r1 - l10 * y0) / l11
    y2 = (r2 - l20 * y0 - l21 * y1) / l22
    y3 = (r3 - l30 * y0 - l31 * y1 - l32 * y2) / l33
    beta[3] = y3 / l33
    beta[2] = (y2 - l32 * beta[3]) / l22
    beta[1] = (y1 - l21 * beta[2] - l31 * beta[3]) / l11
    beta[0] = (y0 - l10 * beta[1] - l20 * beta[2] - l30 * beta[3]) / l00
    return d33 / k


@njit(cache=True, inline="always")
def _accumulate(sums, s, w, q, t, sign):
    sums[0] += sign * w
    sums[1] += sign * q
    sums[2] += sign * s
    sums[3] += sign * w * w
    sums[4] += sign * w * q
    sums[5] += sign * w * s
    sums[6] += sign * q * q
    sums[7] += sign * q * s
    sums[8] += sign * s * s
    sums[9] += sign * t
    sums[10] += sign * w * t
    sums[11] += sign * q * t
    sums[12] += sign * s * t


@njit(cache=True)
def fit_surface(ps, pw, pt, n, curved, min_points, min_spread, outlier_px, iterations, sums, beta):
    """Least-squares surface ``t = c + τ_s s + τ_w w (+ e w²)`` through the first ``n`` points, robustly.

    ``ps`` pixels along the image motion, ``pw`` across it, ``pt`` µs. ``curved`` adds the
    ``w²`` term: under a pure translation the time surface is ``τ_s s + h(w)`` whatever the
    edge's shape, so a curved edge bends it across the motion only. While the farthest point
    is more than ``outlier_px`` pixels from the surface (its time error over the gradient's
    magnitude at the event), it is dropped (moved past the kept ones) and the surface refitted,
    at most ``iterations`` times: one at a time, since a first fit pulled by several outliers
    would make good points look bad too. Returns ``(slot, τ_s, τ_w, c, kept, rms_px)``:
    ``EMITTED`` when a surface stands (µs/px, µs; the first ``kept`` points are the ones it
    fits, ``rms_px`` their rms distance from it), else ``TOO_FEW_POINTS`` or
    ``ILL_CONDITIONED`` (the variance of ``s`` the other terms leave is below ``min_spread``
    px²: the points do not extend along the motion).
    """
    sums[:] = 0.0
    for i in range(n):
        w = pw[i]
        _accumulate(sums, ps[i], w, w * w if curved else 0.0, pt[i], 1.0)
    k = n
    tau_s = tau_w = c = rms_px = 0.0
    for _ in range(iterations + 1):
        if k < min_points:
            return TOO_FEW_POINTS, tau_s, tau_w, c, k, rms_px
        spread = _solve(k, sums, beta, 1e-6)
        if spread < min_spread:
            return ILL_CONDITIONED, tau_s, tau_w, c, k, rms_px
        c, tau_w, e, tau_s = beta[0], beta[1], beta[2], beta[3]
        slope = math.sqrt(tau_s * tau_s + tau_w * tau_w)
        sq = 0.0
        worst, worst_r = 0, 0.0
        for i in range(k):
            w = pw[i]
            r = abs(pt[i] - c - tau_s * ps[i] - (tau_w + e * w) * w)
            sq += r * r
            if r > worst_r:
                worst, worst_r = i, r
        rms_px = math.sqrt(sq / k) / slope if slope > 0.0 else math.inf
        if worst_r <= outlier_px * slope:
            break
        s, w, t = ps[worst], pw[worst], pt[worst]
        _accumulate(sums, s, w, w * w if curved else 0.0, t, -1.0)
        k -= 1
        ps[worst], pw[worst], pt[worst] = ps[k], pw[k], pt[k]
        ps[k], pw[k], pt[k] = s, w, t
    # When the iterations run out with an outlier left, the last surface stands and the rms
    # check judges it.
    return EMITTED, tau_s, tau_w, c, k, rms_px


@njit(cache=True)
def fit_rows(ps, pw, pt, n, min_points, min_spread, outlier_px, iterations, groups):
    """Time per pixel along the image motion from lines of pixels parallel to it, robustly.

    Under a pure translation a pixel sees the signal of the pixel behind it along the motion,
    shifted by the time the image takes to move between them; with equal thresholds even
    their reference levels stay in step, so their first events differ by exactly that time,
    while pixels on different lines see different signals and fire at unrelated phases.
    So each line (points with the same ``round(pw)``) gets its own offset and only the
    slope along ``ps`` is shared: ``t = c_line + τ_s s``. Outliers go one at a time as in
    ``fit_surface``. Returns ``(slot, τ_s, τ_w, c, kept, rms_px)`` like ``fit_surface``:
    ``kept`` counts the points on lines of two or more (the others carry no slope), the
    spread is their variance along ``s`` within their lines, ``τ_w`` the slope of the line
    offsets across the motion (for a rotation term) and ``c`` the offset of the event's line.
    """
    middle = (groups.shape[0] - 1) // 2
    groups[:] = 0.0
    for i in range(n):
        g = middle + np.int64(math.floor(pw[i] + 0.5))
        s, t = ps[i], pt[i]
        groups[g, 0] += 1.0
        groups[g, 1] += s
        groups[g, 2] += t
        groups[g, 3] += s * s
        groups[g, 4] += s * t
    k = n
    tau_s = tau_w = c = rms_px = 0.0
    kept = 0
    for _ in range(iterations + 1):
        sxx = sxy = 0.0
        kept = 0
        for g in range(groups.shape[0]):
            m = groups[g, 0]
            if m >= 2.0:
                kept += np.int64(m)
                sxx += groups[g, 3] - groups[g, 1] * groups[g, 1] / m
                sxy += groups[g, 4] - groups[g, 1] * groups[g, 2] / m
        if kept < min_points:
            return TOO_FEW_POINTS, tau_s, tau_w, c, kept, rms_px
        if sxx < min_spread * kept:
            return ILL_CONDITIONED, tau_s, tau_w, c, kept, rms_px
        tau_s = sxy / sxx
        sq = 0.0
        worst, worst_r = 0, 0.0
        for i in range(k):
            g = middle + np.int64(math.floor(pw[i] + 0.5))
            m = groups[g, 0]
            if m < 2.0:
                continue
            r = abs(pt[i] - (groups[g, 2] - tau_s * groups[g, 1]) / m - tau_s * ps[i])
            sq += r * r
            if r > worst_r:
                worst, worst_r = i, r
        slope = abs(tau_s)
        rms_px = math.sqrt(sq / kept) / slope if slope > 0.0 else math.inf
        if worst_r <= outlier_px * slope:
            break
        s, w, t = ps[worst], pw[worst], pt[worst]
        g = middle + np.int64(math.floor(w + 0.5))
        groups[g, 0] -= 1.0
        groups[g, 1] -= s
        groups[g, 2] -= t
        groups[g, 3] -= s * s
        groups[g, 4] -= s * t
        k -= 1
        ps[worst], pw[worst], pt[worst] = ps[k], pw[k], pt[k]
        ps[k], pw[k], pt[k] = s, w, t
    # Offsets of the lines against their position across the motion: τ_w (weighted by points).
    sw = so = sww = swo = total = 0.0
    for g in range(groups.shape[0]):
        m = groups[g, 0]
        if m >= 1.0:
            w, offset = float(g - middle), (groups[g, 2] - tau_s * groups[g, 1]) / m
            total += m
            sw += m * w
            so += m * offset
            sww += m * w * w
            swo += m * w * offset
    spread_w = sww - sw * sw / total
    tau_w = (swo - sw * so / total) / spread_w if spread_w > 0.0 else 0.0
    if groups[middle, 0] > 0.0:
        c = (groups[middle, 2] - tau_s * groups[middle, 1]) / groups[middle, 0]
    else:
        c = so / total - tau_w * sw / total
    return EMITTED, tau_s, tau_w, c, kept, rms_px


@njit(cache=True)
def process(ts, xs, ys, ps, ip, fp, surface, hold, last, prev, motion, sample_of, points, at_cache, at_update,
            velocity, first_update, ps_, pw, pt, sums, beta, groups, counts, out, quality, n_out, index0, t_hi):
    """Run time-ordered events through the estimator; returns ``(n_out, status, t_hi)``.

    ``surface[p, (y + r) * (w + 2r) + x + r]`` is the last first event (µs) of pixel (x, y) and
    polarity p (one plane per polarity: a fit reads one cache line per row) (a border of ``r = radius`` pixels stays ``NEVER``); ``hold[y * w + x, p]`` its
    measured hold (µs, 0 = none yet); ``last`` its last event of any kind (used with a burst
    gap); ``prev[y * w + x]`` the pixel's last estimate (z, t) for the consistency rule.
    ``A t`` of pixel ``(x, y)`` is taken at ``points[sample_of[y * w + x]]`` and cached per
    sample and update. ``velocity[j - first_update]`` is (tx, ty, tz[, wx, wy, wz]) of update
    j. Estimates go to ``out[n_out:]`` (``DEPTH_DTYPE``) and ``quality[n_out:]``. ``t_hi`` is
    the latest time seen before; an earlier event stops the call with ``UNSORTED`` before
    it changes any state (``n_out`` and ``counts`` then cover the events before it).
    """
    width, height, radius = ip[I_WIDTH], ip[I_HEIGHT], ip[I_RADIUS]
    t0, dt, latency, update_every = ip[I_T0], ip[I_DT], ip[I_LATENCY], ip[I_UPDATE_EVERY]
    both, min_points, iterations = ip[I_BOTH] != 0, ip[I_MIN_POINTS], ip[I_ITERATIONS]
    refractory_us, burst_gap_us, window_us = ip[I_REFRACTORY], ip[I_BURST_GAP], ip[I_WINDOW]
    consistency_us, max_hold, record_rejected = ip[I_CONSISTENCY_WINDOW], ip[I_MAX_HOLD], ip[I_RECORD_REJECTED] != 0
    fx, fy, cx, cy = fp[F_FX], fp[F_FY], fp[F_CX], fp[F_CY]
    outlier_px, max_rms, min_spread = fp[F_OUTLIER], fp[F_MAX_RMS], fp[F_MIN_SPREAD]
    min_depth, max_depth, min_denominator = fp[F_MIN_DEPTH], fp[F_MAX_DEPTH], fp[F_MIN_DENOMINATOR]
    window_depth, refractory_depth, consistency = fp[F_WINDOW_DEPTH], fp[F_REFRACTORY_DEPTH], fp[F_CONSISTENCY]
    hold_px, ahead_px, turn, trim_px = fp[F_HOLD_PX], fp[F_AHEAD_PX], fp[F_TURN], fp[F_TRIM_PX]
    model = ip[I_MODEL]
    rotation = velocity.shape[1] >= 6
    row = width + 2 * radius
    step, step_start, step_end, update = np.int64(0), np.int64(1), np.int64(0), np.int64(0)
    j = 0
    for i in range(ts.shape[0]):
        t = ts[i]
        if t < t_hi:
            return n_out, UNSORTED, t_hi
        t_hi = t
        x, y = np.int64(xs[i]), np.int64(ys[i])
        if x >= width or y >= height:
            counts[OUT_OF_BOUNDS] += 1
            continue
        if t < t0:
            counts[BEFORE_T0] += 1
            continue
        if t >= step_end or t < step_start:  # divisions only when the step changes
            k = (t - t0) // dt
            step_start, step_end = t0 + k * dt, t0 + (k + 1) * dt
            step = k + latency  # the output step; it holds update (step - 1) // U (docs/semantics.md)
            update = (step - 1) // update_every
            j = update - first_update
            if j < 0 or j >= velocity.shape[0]:
                return n_out, NO_VELOCITY, t_hi
            if update != motion[M_UPDATE]:
                follow_motion(motion, velocity[j], update, t0 + update * update_every * dt, turn)
        polarity = 1 if ps[i] != 0 else 0
        pixel = y * width + x
        sample = sample_of[pixel]
        if at_update[sample] != update:
            at_x, at_y = velocity_term(velocity[j, 0], velocity[j, 1], velocity[j, 2], points[sample, 0],
                                       points[sample, 1], fx, fy, cx, cy)
            at_cache[sample, 0], at_cache[sample, 1] = at_x, at_y
            at_cache[sample, 2] = math.sqrt(at_x * at_x + at_y * at_y)  # px*m/s
            at_update[sample] = update
        at_x, at_y, speed = at_cache[sample, 0], at_cache[sample, 1], at_cache[sample, 2]
        # 1. First-event rule.
        held = np.int64(hold[pixel, polarity])
        if held == 0:  # no fit measured this pixel's edges yet
            held = refractory_us
            if refractory_depth > 0.0 and speed > 0.0:  # the time a surface that deep takes per pixel
                held = max(held, np.int64(refractory_depth / speed * 1e6))
        cell = (y + radius) * row + x + radius
        if burst_gap_us > 0:
            gap = t - last[pixel, polarity]
            last[pixel, polarity] = t
            if gap < burst_gap_us:
                counts[BURST] += 1
                continue
        if t - surface[polarity, cell] < held:
            counts[BURST] += 1
            continue
        surface[polarity, cell] = t
        if speed <= 0.0:
            counts[NO_MOTION] += 1
            continue
        # 2. Gather the recent first events the edge has crossed.
        window = window_us
        if window_depth > 0.0:
            window = max(window, np.int64(window_depth * radius / speed * 1e6))
        if turn > 0.0:  # nothing from before the camera's last turn: another motion made it
            window = min(window, t - np.int64(motion[M_SINCE]))
        fu, fv = at_x / speed, at_y / speed
        plane, other = surface[polarity], surface[1 - polarity]
        n = 0
        for dv in range(-radius, radius + 1):
            # The columns the edge has crossed in this row: du * fu + dv * fv <= ahead_px.
            lo, hi = -radius, radius
            if fu > 1e-9:
                hi = min(hi, np.int64(math.floor((ahead_px - dv * fv) / fu)))
            elif fu < -1e-9:
                lo = max(lo, np.int64(math.ceil((ahead_px - dv * fv) / fu)))
            elif dv * fv > ahead_px:
                hi = lo - 1
            base = cell + dv * row
            for du in range(lo, hi + 1):
                along, across = du * fu + dv * fv, dv * fu - du * fv
                age = t - plane[base + du]
                ps_[n], pw[n], pt[n] = along, across, -age
                n += age <= window
                if both:
                    age = t - other[base + du]
                    ps_[n], pw[n], pt[n] = along, across, -age
                    n += age <= window
            if dv == 0 and not lo <= 0 <= hi:  # the event itself always counts
                ps_[n], pw[n], pt[n] = 0.0, 0.0, 0.0
                n += 1
        # 3. Fit and check.
        if model == MODEL_ROWS:
            slot, tau_s, tau_w, c, kept, rms = fit_rows(ps_, pw, pt, n, min_points, min_spread, outlier_px, iterations,
                                                        groups)
        else:
            slot, tau_s, tau_w, c, kept, rms = fit_surface(ps_, pw, pt, n, model == MODEL_CURVED, min_points,
                                                           min_spread, outlier_px, iterations, sums, beta)
        if trim_px > 0.0 and slot == EMITTED and model != MODEL_ROWS:
            # The window cuts on measured times: near its ends only the points that fired late
            # (old end) or early (the present) are in, which flattens the surface. Cutting on
            # the fitted times is unbiased: drop the points the fit puts within ``trim_px``
            # pixels of either end, and refit.
            margin = trim_px * math.sqrt(tau_s * tau_s + tau_w * tau_w)
            e = beta[2]
            m = 0
            for i2 in range(kept):
                fitted = c + tau_s * ps_[i2] + (tau_w + e * pw[i2]) * pw[i2]
                if -window + margin <= fitted <= -margin:
                    ps_[m], pw[m], pt[m] = ps_[i2], pw[i2], pt[i2]
                    m += 1
            if m < kept:
                slot, tau_s, tau_w, c, kept, rms = fit_surface(ps_, pw, pt, m, model == MODEL_CURVED, min_points,
                                                               min_spread, outlier_px, iterations, sums, beta)
        a, b = tau_s * fu - tau_w * fv, tau_s * fv + tau_w * fu  # ∇T at the event, µs/px along u and v
        if slot == EMITTED:
            if hold_px > 0.0:  # this edge's burst lasts about its ramp's width: hold_px pixels
                hold[pixel, polarity] = min(max_hold, np.int64(hold_px * math.sqrt(a * a + b * b)) + 1)
            if rms > max_rms:
                slot = BAD_FIT
        z = 0.0
        gx, gy = a * 1e-6, b * 1e-6  # s/px
        if slot == EMITTED:
            z = at_x * gx + at_y * gy
            if rotation:
                bw_x, bw_y = rotational_flow(velocity[j, 3], velocity[j, 4], velocity[j, 5], float(x), float(y),
                                             fx, fy, cx, cy)
                denominator = 1.0 - (bw_x * gx + bw_y * gy)
                if denominator < min_denominator:
                    slot = ROTATION_DOMINATED
                else:
                    z /= denominator
        if slot == EMITTED:
            if z <= min_depth:
                slot = TOO_NEAR
            elif z >= max_depth:
                slot = TOO_FAR
        if slot == EMITTED and consistency > 0.0:
            before, when = prev[pixel, 0], prev[pixel, 1]
            prev[pixel, 0], prev[pixel, 1] = z, t
            if t - when > consistency_us or abs(z - before) > consistency * before:
                slot = INCONSISTENT
        counts[slot] += 1
        if slot != EMITTED:
            if not record_rejected:
                continue
            z = math.nan
        estimate, q = out[n_out], quality[n_out]
        estimate.t, estimate.x, estimate.y, estimate.z, estimate.step = step_end + latency * dt, x, y, z, step
        q.t_event, q.points, q.rms_px, q.gx, q.gy, q.index, q.reason = t, kept, rms, gx, gy, index0 + i, slot
        n_out += 1
    return n_out, OK, t_hi
