"""Depth from the local slope of the time surface (beyond the paper; DESIGN "Beyond the paper").

The numba core of the time-surface estimator; the streaming API and the parameters are in
``tofnet.kernels.time_surface_estimator``, the method and the measurements behind the
defaults in docs/time_surface.md. Per pixel and polarity the state holds the time (µs) of
the last *first event* of an edge: the surface ``T(u, v)``. Per event:

1. first-event rule: an event of a pixel and polarity whose last first event is more recent
   than its hold (``hold_px`` times the time per pixel the last fit there measured, else the
   refractory period) is part of the same edge's burst: dropped;
2. gather the first events of the same polarity within ``radius`` pixels that the edge has
   already crossed (at most ``ahead_px`` along the image motion ``A t``), no older than the
   window nor than the camera's last turn;
3. fit the time along the motion, per line of pixels parallel to it (``fit_rows``) or as a
   plane (``fit_plane``), dropping the farthest point while it is more than ``outlier_px``
   pixels off, at most ``iterations`` times; check points, spread and rms;
4. ``∇T`` (s/px) is the time of travel (DESIGN eq. 8: ``td = dT/du``, positive for motion
   towards +u): ``Z = (A t)·∇T``, or ``(A t)·∇T / (1 − (B ω)·∇T)`` with a rotation.

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
(I_WIDTH, I_HEIGHT, I_RADIUS, I_T0, I_DT, I_LATENCY, I_UPDATE_EVERY, I_MIN_POINTS, I_ITERATIONS,
 I_REFRACTORY, I_WINDOW, I_CONSISTENCY_WINDOW, I_MAX_HOLD, I_RECORD_REJECTED, I_MODEL, N_IP) = range(16)
(F_FX, F_FY, F_CX, F_CY, F_OUTLIER, F_MAX_RMS, F_MIN_SPREAD, F_MIN_DEPTH, F_MAX_DEPTH, F_MIN_DENOMINATOR,
 F_WINDOW_DEPTH, F_REFRACTORY_DEPTH, F_CONSISTENCY, F_HOLD_PX, F_AHEAD_PX, F_TURN, F_TRIM_PX, N_FP) = range(18)
# Motion state: the velocity the current epoch started with, its start (µs), the last update seen.
M_VX, M_VY, M_VZ, M_SINCE, M_UPDATE, N_MOTION = range(6)
# Per sample of ``A t`` and velocity update: A t (px*m/s), |A t|, its direction, the refractory
# period and the window it implies (µs).
A_X, A_Y, A_SPEED, A_FU, A_FV, A_REFRACTORY, A_WINDOW, N_A = range(8)
# Per line of a ``fit_rows`` fit: raw sums (count, s, t, s², s t), means of s and t, centred sums.
L_M, L_S, L_T, L_SS, L_ST, L_MEAN_S, L_MEAN_T, L_CSS, L_CST, N_L = range(10)
# Fit models (``I_MODEL``): a plane, or lines along the motion with a shared slope.
MODEL_PLANE, MODEL_ROWS = range(2)
MODELS = ("plane", "rows")
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
def fit_plane(ps, pw, pt, n, min_points, min_spread, outlier_px, iterations):
    """Least-squares plane ``t = c + τ_s s + τ_w w`` through the first ``n`` points, robustly.

    ``ps`` pixels along the image motion, ``pw`` across it, ``pt`` µs (Benosman et al. 2014's
    local plane, in the motion's frame). While the farthest point is more than ``outlier_px``
    pixels from the plane (its time error over the gradient's magnitude), it is dropped (moved
    past the kept ones) and the plane refitted, at most ``iterations`` times: one at a time,
    since a first fit pulled by several outliers would make good points look bad too. Returns
    ``(slot, τ_s, τ_w, c, kept, rms_px)``: ``EMITTED`` when a plane stands (µs/px, µs; the
    first ``kept`` points are the ones it fits, ``rms_px`` their rms distance from it in
    pixels), else ``TOO_FEW_POINTS`` or ``ILL_CONDITIONED`` (the variance of ``s`` that ``w``
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
            return TOO_FEW_POINTS, tau_s, tau_w, c, k, rms_px
        ms, mw, mt = ss / k, sw / k, st / k
        css, csw, cww = sss / k - ms * ms, ssw / k - ms * mw, sww / k - mw * mw
        cst, cwt = sst / k - ms * mt, swt / k - mw * mt
        if cww > 1e-9:  # points across the motion too: the full plane
            spread = css - csw * csw / cww
            if spread < min_spread:
                return ILL_CONDITIONED, tau_s, tau_w, c, k, rms_px
            det = css * cww - csw * csw
            tau_s = (cst * cww - cwt * csw) / det
            tau_w = (cwt * css - cst * csw) / det
        else:  # one line along the motion: its slope, nothing across
            if css < min_spread:
                return ILL_CONDITIONED, tau_s, tau_w, c, k, rms_px
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
    return EMITTED, tau_s, tau_w, c, k, rms_px


@njit(cache=True, inline="always")
def _line_stats(lines, g):
    """Means and centred sums of line ``g`` from its raw sums (NaN means: fewer than 2 points)."""
    m = lines[g, L_M]
    if m >= 2.0:
        inv = 1.0 / m
        lines[g, L_MEAN_S], lines[g, L_MEAN_T] = lines[g, L_S] * inv, lines[g, L_T] * inv
        lines[g, L_CSS] = lines[g, L_SS] - lines[g, L_S] * lines[g, L_MEAN_S]
        lines[g, L_CST] = lines[g, L_ST] - lines[g, L_S] * lines[g, L_MEAN_T]
    else:
        lines[g, L_MEAN_S] = lines[g, L_MEAN_T] = math.nan
        lines[g, L_CSS] = lines[g, L_CST] = 0.0


@njit(cache=True)
def fit_rows(ps, pt, pg, n, min_points, min_spread, outlier_px, iterations, lines, used):
    """Time per pixel along the image motion from lines of pixels parallel to it, robustly.

    Under a pure translation a pixel sees the signal of the pixel behind it along the motion,
    shifted by the time the image takes to move between them; with equal thresholds even
    their reference levels stay in step, so their first events differ by exactly that time,
    while pixels on different lines see different signals and fire at unrelated phases, and
    a curved edge bends the surface across the motion only. So each line (``pg``: index of
    the point's line across the motion, the event's is ``middle``) gets its own offset and
    only the slope along ``ps`` is shared: ``t = c_line + τ_s s``. Outliers go one at a time
    as in ``fit_plane``. ``lines`` (``N_L`` columns, zero on entry and on return) and
    ``used`` are scratch. Returns ``(slot, τ_s, τ_w, c, kept, rms_px)`` like ``fit_plane``:
    ``kept`` counts the points on lines of two or more (the others carry no slope), the
    spread is their variance along ``s`` within their lines, ``τ_w`` the slope of the lines'
    offsets across the motion and ``c`` the offset of the event's line.
    """
    middle = (lines.shape[0] - 1) // 2
    n_used = 0
    for i in range(n):
        g = pg[i]
        if lines[g, L_M] == 0.0:
            used[n_used] = g
            n_used += 1
        s, t = ps[i], pt[i]
        lines[g, L_M] += 1.0
        lines[g, L_S] += s
        lines[g, L_T] += t
        lines[g, L_SS] += s * s
        lines[g, L_ST] += s * t
    sxx = sxy = 0.0
    kept = 0
    for j in range(n_used):
        g = used[j]
        _line_stats(lines, g)
        sxx += lines[g, L_CSS]
        sxy += lines[g, L_CST]
        if lines[g, L_M] >= 2.0:
            kept += np.int64(lines[g, L_M])
    k = n
    tau_s = tau_w = c = rms_px = 0.0
    slot = EMITTED
    for _ in range(iterations + 1):
        if kept < min_points:
            slot = TOO_FEW_POINTS
            break
        if sxx < min_spread * kept:
            slot = ILL_CONDITIONED
            break
        tau_s = sxy / sxx
        sq = 0.0
        worst, worst_r = 0, 0.0
        for i in range(k):
            g = pg[i]
            r = abs(pt[i] - lines[g, L_MEAN_T] - tau_s * (ps[i] - lines[g, L_MEAN_S]))
            if r > worst_r:  # False for NaN: a line of one point carries no slope
                worst, worst_r = i, r
            if r == r:
                sq += r * r
        slope = abs(tau_s)
        rms_px = math.sqrt(sq / kept) / slope if slope > 0.0 else math.inf
        if worst_r <= outlier_px * slope:
            break
        s, t, g = ps[worst], pt[worst], pg[worst]
        sxx -= lines[g, L_CSS]
        sxy -= lines[g, L_CST]
        kept -= np.int64(lines[g, L_M]) if lines[g, L_M] >= 2.0 else 0
        lines[g, L_M] -= 1.0
        lines[g, L_S] -= s
        lines[g, L_T] -= t
        lines[g, L_SS] -= s * s
        lines[g, L_ST] -= s * t
        _line_stats(lines, g)
        sxx += lines[g, L_CSS]
        sxy += lines[g, L_CST]
        kept += np.int64(lines[g, L_M]) if lines[g, L_M] >= 2.0 else 0
        k -= 1
        ps[worst], pt[worst], pg[worst] = ps[k], pt[k], pg[k]
        ps[k], pt[k], pg[k] = s, t, g
    if slot == EMITTED:
        # The lines' offsets against their position across the motion: τ_w (weighted by points).
        sw = so = sww = swo = total = 0.0
        for j in range(n_used):
            g = used[j]
            m = lines[g, L_M]
            if m >= 1.0:
                w, offset = float(g - middle), (lines[g, L_T] - tau_s * lines[g, L_S]) / m
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
        g = used[j]
        lines[g, L_M] = lines[g, L_S] = lines[g, L_T] = lines[g, L_SS] = lines[g, L_ST] = 0.0
    return slot, tau_s, tau_w, c, kept, rms_px


@njit(cache=True)
def _sample(at_cache, sample, velocity, j, points, fx, fy, cx, cy, refractory_us, refractory_depth, window_us,
            window_depth, radius):
    """Fill ``at_cache[sample]`` for velocity row ``j`` (``A_*`` columns)."""
    at_x, at_y = velocity_term(velocity[j, 0], velocity[j, 1], velocity[j, 2], points[sample, 0], points[sample, 1],
                               fx, fy, cx, cy)
    speed = math.sqrt(at_x * at_x + at_y * at_y)
    row = at_cache[sample]
    row[A_X], row[A_Y], row[A_SPEED] = at_x, at_y, speed
    row[A_FU], row[A_FV] = (at_x / speed, at_y / speed) if speed > 0.0 else (0.0, 0.0)
    # The time the image of a surface that deep takes per pixel (refractory) and per radius (window).
    refractory, window = float(refractory_us), float(window_us)
    if speed > 0.0:
        if refractory_depth > 0.0:
            refractory = max(refractory, math.floor(refractory_depth / speed * 1e6))
        if window_depth > 0.0:
            window = max(window, math.floor(window_depth * radius / speed * 1e6))
    row[A_REFRACTORY], row[A_WINDOW] = refractory, window


@njit(cache=True)
def process(ts, xs, ys, ps, ip, fp, surface, hold, prev, motion, sample_of, points, at_cache, at_update,
            velocity, first_update, ps_, pw, pt, pg, lines, used, counts, out, quality, n_out, index0, t_hi):
    """Run time-ordered events through the estimator; returns ``(n_out, status, t_hi)``.

    ``surface[p, (y + r) * (w + 2r) + x + r]`` is the last first event (µs) of pixel (x, y) and
    polarity p (one plane per polarity, so a fit reads one cache line per row; a border of
    ``r = radius`` pixels stays ``NEVER``); ``hold[y * w + x, p]`` its measured hold (µs, 0 =
    none yet); ``prev[y * w + x]`` the pixel's last estimate (z, t) for the consistency rule.
    ``A t`` of pixel ``(x, y)`` is taken at ``points[sample_of[y * w + x]]`` and cached per
    sample and update (``at_cache``, ``at_update``). ``velocity[j - first_update]`` is (tx, ty,
    tz[, wx, wy, wz]) of update j. ``ps_``, ``pw``, ``pt``, ``pg``, ``lines``, ``used`` are the
    fits' scratch. Estimates go to ``out[n_out:]`` (``DEPTH_DTYPE``) and ``quality[n_out:]``.
    ``t_hi`` is the latest time seen before; an earlier event stops the call with
    ``UNSORTED`` before it changes any state (``n_out`` and ``counts`` cover the events
    before it).
    """
    width, height, radius = ip[I_WIDTH], ip[I_HEIGHT], ip[I_RADIUS]
    t0, dt, latency, update_every = ip[I_T0], ip[I_DT], ip[I_LATENCY], ip[I_UPDATE_EVERY]
    min_points, iterations = ip[I_MIN_POINTS], ip[I_ITERATIONS]
    refractory_us, window_us = ip[I_REFRACTORY], ip[I_WINDOW]
    consistency_us, max_hold, record_rejected = ip[I_CONSISTENCY_WINDOW], ip[I_MAX_HOLD], ip[I_RECORD_REJECTED] != 0
    rows_model = ip[I_MODEL] == MODEL_ROWS
    fx, fy, cx, cy = fp[F_FX], fp[F_FY], fp[F_CX], fp[F_CY]
    outlier_px, max_rms, min_spread = fp[F_OUTLIER], fp[F_MAX_RMS], fp[F_MIN_SPREAD]
    min_depth, max_depth, min_denominator = fp[F_MIN_DEPTH], fp[F_MAX_DEPTH], fp[F_MIN_DENOMINATOR]
    window_depth, refractory_depth, consistency = fp[F_WINDOW_DEPTH], fp[F_REFRACTORY_DEPTH], fp[F_CONSISTENCY]
    hold_px, ahead_px, turn, trim_px = fp[F_HOLD_PX], fp[F_AHEAD_PX], fp[F_TURN], fp[F_TRIM_PX]
    rotation = velocity.shape[1] >= 6
    row = width + 2 * radius
    middle = (lines.shape[0] - 1) // 2
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
            _sample(at_cache, sample, velocity, j, points, fx, fy, cx, cy, refractory_us, refractory_depth,
                    window_us, window_depth, radius)
            at_update[sample] = update
        a_t = at_cache[sample]
        # 1. First-event rule: a hold measured by the last fit here, else the refractory period.
        held = np.int64(hold[pixel, polarity])
        if held == 0:
            held = np.int64(a_t[A_REFRACTORY])
        cell = (y + radius) * row + x + radius
        if t - surface[polarity, cell] < held:
            counts[BURST] += 1
            continue
        surface[polarity, cell] = t
        speed = a_t[A_SPEED]
        if speed <= 0.0:
            counts[NO_MOTION] += 1
            continue
        at_x, at_y, fu, fv = a_t[A_X], a_t[A_Y], a_t[A_FU], a_t[A_FV]
        # 2. Gather the recent first events of the pixels the edge has crossed: at most
        # ``ahead_px`` along the motion (the pixels ahead still hold an older edge's times).
        window = np.int64(a_t[A_WINDOW])
        if turn > 0.0:  # nothing from before the camera's last turn: another motion made it
            window = min(window, t - np.int64(motion[M_SINCE]))
        plane = surface[polarity]
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
                age = t - plane[base + du]
                if age <= window:
                    across = across0 - du * fv
                    ps_[n], pw[n], pt[n] = along0 + du * fu, across, -age
                    pg[n] = middle + np.int64(math.floor(across + 0.5))
                    n += 1
            if dv == 0 and not lo <= 0 <= hi:  # the event itself always counts
                ps_[n], pw[n], pt[n], pg[n] = 0.0, 0.0, 0.0, middle
                n += 1
        # 3. Fit and check.
        if rows_model:
            slot, tau_s, tau_w, c, kept, rms = fit_rows(ps_, pt, pg, n, min_points, min_spread, outlier_px,
                                                        iterations, lines, used)
        else:
            slot, tau_s, tau_w, c, kept, rms = fit_plane(ps_, pw, pt, n, min_points, min_spread, outlier_px,
                                                         iterations)
            if trim_px > 0.0 and slot == EMITTED:
                # The window cuts on measured times: near its ends only the points that fired
                # late (old end) or early (the present) are in, which flattens the plane.
                # Cutting on the fitted times is unbiased: drop the points the plane puts
                # within ``trim_px`` pixels of either end, and refit.
                margin = trim_px * math.sqrt(tau_s * tau_s + tau_w * tau_w)
                m = 0
                for i2 in range(kept):
                    fitted = c + tau_s * ps_[i2] + tau_w * pw[i2]
                    if -window + margin <= fitted <= -margin:
                        ps_[m], pw[m], pt[m] = ps_[i2], pw[i2], pt[i2]
                        m += 1
                if m < kept:
                    slot, tau_s, tau_w, c, kept, rms = fit_plane(ps_, pw, pt, m, min_points, min_spread, outlier_px,
                                                                 iterations)
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
