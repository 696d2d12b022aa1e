"""Depth from the local slope of the time surface (beyond the paper; docs/time_surface.md).

The numba core of the time-surface estimator; the streaming API and the parameters are in
``tofnet.kernels.time_surface_estimator``. Per pixel and polarity the state holds the time
(µs) of the last *first event* of an edge: the surface ``T(u, v)``. Per event: the
first-event rule (a burst's later events are dropped), gather the first events the edge
has crossed, fit the time along the image motion (``fit_rows`` or ``fit_plane``), check the
fit, and ``Z = (A t)·∇T`` (``∇T`` s/px, the depth neuron's ``td``), or eq. 7 with a
rotation. Each step and its parameters: docs/time_surface.md, "1. Method". Every event
ends in exactly one count slot (``COUNT_NAMES``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tofnet.kernels.time_of_travel import prefetch
from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.time_surface_fit import FIT_ILL_CONDITIONED, FIT_OVER_RMS, FIT_TOO_FEW, fit_plane, fit_rows
from tofnet.kernels.velocity import sampled_velocity_term, velocity_term

NEVER = -(1 << 62)  # "no first event yet" (µs)

#: Count slots: where each event ended. Drops of events, rejections of estimates, emitted.
(OUT_OF_BOUNDS, BEFORE_T0, BURST, NO_MOTION, NOTHING_BEHIND, TOO_FEW_POINTS, ILL_CONDITIONED, BAD_FIT,
 ROTATION_DOMINATED, TOO_NEAR, TOO_FAR, INCONSISTENT, SAME_STEP, EMITTED, N_COUNTS) = range(15)
COUNT_NAMES = ("out_of_bounds", "before_t0", "burst", "no_motion", "nothing_behind", "too_few_points",
               "ill_conditioned", "bad_fit", "rotation_dominated", "too_near", "too_far", "inconsistent", "same_step",
               "emitted")
DROP_SLOTS = (OUT_OF_BOUNDS, BEFORE_T0, BURST)  # not the first event of an edge
REJECT_SLOTS = tuple(range(NO_MOTION, EMITTED))  # a first event whose estimate was rejected

# Integer parameters (``ip``) and float parameters (``fp``), by slot.
(I_WIDTH, I_HEIGHT, I_RADIUS, I_T0, I_DT, I_LATENCY, I_UPDATE_EVERY, I_MIN_POINTS, I_ITERATIONS,
 I_REFRACTORY, I_WINDOW, I_CONSISTENCY_WINDOW, I_MAX_HOLD, I_RECORD_REJECTED, I_MODEL, I_PER_PIXEL, I_PINHOLE,
 N_IP) = range(18)
(F_FX, F_FY, F_CX, F_CY, F_OUTLIER, F_MAX_RMS, F_MIN_SPREAD, F_MIN_DEPTH, F_MAX_DEPTH, F_MIN_DENOMINATOR,
 F_WINDOW_DEPTH, F_REFRACTORY_REACH, F_CONSISTENCY, F_HOLD_PX, F_AHEAD_PX, F_TURN, F_TRIM_PX,
 F_RFX, F_RFY, F_RCX, F_RCY, F_HOLD_RMS, F_BEHIND_REACH, F_WINDOW_PX, N_FP) = range(25)  # F_R*: B ω's intrinsics
# F_*_REACH: a depth (m) times 1e6 µs/s; over |A t| (px m/s) it is the time (µs) per pixel of a surface that deep.
# Motion state: the velocity the current epoch started with, its start (µs), the last update seen.
M_VX, M_VY, M_VZ, M_SINCE, M_UPDATE, N_MOTION = range(6)
# Fit models (``I_MODEL``): a plane, or lines along the motion with a shared slope.
MODEL_PLANE, MODEL_ROWS = range(2)
MODELS = ("plane", "rows")
# Status of a call.
OK, UNSORTED, NO_VELOCITY = range(3)
#: Events between a prefetch of a pixel's hold and surface rows and their use.
PREFETCH = 8


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


@njit(cache=True, inline="always")
def _velocity_term_at(x, y, pixel, per_pixel, pinhole, sample_of, points, velocity, j, fx, fy, cx, cy):
    """``A t`` (px*m/s) for pixel (x, y) under velocity row ``j``, through the lens of
    ``points`` (one ``tofnet.kernels.lens.sample_table`` row per sample: the pixel or its patch);
    ``pinhole`` (per pixel, no lens): at the pixel itself, the same numbers without reading the table."""
    if pinhole:
        at_x, at_y = velocity_term(velocity[j, 0], velocity[j, 1], velocity[j, 2], float(x), float(y), fx, fy, cx, cy)
    else:
        sample = pixel if per_pixel else sample_of[pixel]
        at_x, at_y = sampled_velocity_term(velocity[j, 0], velocity[j, 1], velocity[j, 2], points[sample], fx, fy, cx,
                                           cy)
    return at_x, at_y



@njit(cache=True, inline="always")
def _behind(a: float, speed2: float) -> tuple[int, int]:
    """``floor(f + 0.5)`` and ``floor(2 f + 0.5)`` of the unit motion's component ``f = a / √speed2``
    (``|f| <= 1``), from squares and without branches: the steps (px) to the pixels 1 and 2 px
    behind along one axis (a tie rounds up, as ``floor``)."""
    a2 = a * a
    quarter, half, three = 0.0625 * speed2, 0.25 * speed2, 0.5625 * speed2  # |f| = 1/4, 1/2, 3/4
    up_one, up_two = np.int64(a2 >= half), np.int64(a2 >= quarter) + np.int64(a2 >= three)
    down_one, down_two = np.int64(a2 > half), np.int64(a2 > quarter) + np.int64(a2 > three)
    positive = a > 0.0
    return (up_one if positive else -down_one), (up_two if positive else -down_two)


@njit(cache=True)
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
            ps_[n], pw[n], pt[n], pg[n] = 0.0, 0.0, 0.0, middle
            n += 1
    return n

@njit(cache=True)
def process(ts, xs, ys, ps, ip, fp, surface, hold, prev, last_step, motion, sample_of, points, velocity, first_update,
            ps_, pw, pt, pg, lines, used, counts, out, quality, n_out, index0, t_hi):
    """Run time-ordered events through the estimator; returns ``(n_out, status, t_hi)``.

    ``surface[p, (y + r) * (w + 2r) + x + r]`` is the last first event (µs) of pixel (x, y) and
    polarity p (one plane per polarity, so a fit reads one cache line per row; a border of
    ``r = radius`` pixels stays ``NEVER``); ``hold[y * w + x, p]`` its measured hold (µs, 0 =
    none yet); ``prev[y * w + x]`` the pixel's last estimate (z, t) for the consistency rule;
    ``last_step[y * w + x]`` the output step of its last estimate (at most one per pixel and step).
    ``A t`` of pixel ``(x, y)`` is taken at the pixel (``I_PER_PIXEL``) or at
    ``points[sample_of[y * w + x]]``, computed only for events that need it (a pixel's first
    hold, first events). ``velocity[j - first_update]`` is (tx, ty, tz[, wx, wy, wz]) of update j.
    ``ps_``, ``pw``, ``pt``, ``pg``, ``lines``, ``used`` are the fits' scratch. Estimates go to
    ``out[n_out:]`` (``DEPTH_DTYPE``) and ``quality[n_out:]``. ``t_hi`` is the latest time seen
    before; an earlier event stops the call with ``UNSORTED`` before it changes any state
    (``n_out`` and ``counts`` cover the events before it).
    """
    width, height, radius = ip[I_WIDTH], ip[I_HEIGHT], ip[I_RADIUS]
    t0, dt, latency, update_every = ip[I_T0], ip[I_DT], ip[I_LATENCY], ip[I_UPDATE_EVERY]
    min_points, iterations = ip[I_MIN_POINTS], ip[I_ITERATIONS]
    refractory_us, window_us = ip[I_REFRACTORY], ip[I_WINDOW]
    consistency_us, max_hold, record_rejected = ip[I_CONSISTENCY_WINDOW], ip[I_MAX_HOLD], ip[I_RECORD_REJECTED] != 0
    rows_model, per_pixel, pinhole = ip[I_MODEL] == MODEL_ROWS, ip[I_PER_PIXEL] != 0, ip[I_PINHOLE] != 0
    fx, fy, cx, cy = fp[F_FX], fp[F_FY], fp[F_CX], fp[F_CY]
    outlier_px, max_rms, min_spread = fp[F_OUTLIER], fp[F_MAX_RMS], fp[F_MIN_SPREAD]
    min_depth, max_depth, min_denominator = fp[F_MIN_DEPTH], fp[F_MAX_DEPTH], fp[F_MIN_DENOMINATOR]
    window_depth, refractory_reach, consistency = fp[F_WINDOW_DEPTH], fp[F_REFRACTORY_REACH], fp[F_CONSISTENCY]
    hold_px, ahead_px, turn, trim_px = fp[F_HOLD_PX], fp[F_AHEAD_PX], fp[F_TURN], fp[F_TRIM_PX]
    hold_rms, behind_reach, window_px = fp[F_HOLD_RMS], fp[F_BEHIND_REACH], fp[F_WINDOW_PX]
    rotation = velocity.shape[1] >= 6
    # a fit this far off its points is rejected (bad_fit) and sets no hold: unless it is recorded, the fit may stop
    give_up_rms = math.inf if record_rejected else max(max_rms, hold_rms) if hold_px > 0.0 else max_rms
    row = width + 2 * radius
    middle = (lines.shape[0] - 1) // 2
    step, step_start, step_end, update = np.int64(0), np.int64(1), np.int64(0), np.int64(0)
    j = 0
    n_events, plane_size = ts.shape[0], surface.shape[1]
    flat_surface, flat_hold = surface.reshape(-1), hold.reshape(-1)
    flat_points, points_columns = points.reshape(-1), points.shape[1]
    for i in range(n_events):
        if i + PREFETCH < n_events:  # what a first event would read: the rows of its square, its A t's sample
            xq, yq = np.int64(xs[i + PREFETCH]), np.int64(ys[i + PREFETCH])
            if xq < width and yq < height:
                pq = 1 if ps[i + PREFETCH] != 0 else 0
                prefetch(flat_hold, 2 * (yq * width + xq) + pq)
                cq = pq * plane_size + (yq + radius) * row + xq + radius
                for dq in range(-radius, radius + 1):
                    prefetch(flat_surface, cq + dq * row)
                if not pinhole:
                    sq = yq * width + xq if per_pixel else sample_of[yq * width + xq]
                    prefetch(flat_points, sq * points_columns)
                    prefetch(flat_points, sq * points_columns + points_columns - 1)
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
        cell = (y + radius) * row + x + radius
        # 1. First-event rule: a hold measured by the last fit here, else the refractory period:
        # the time a surface at ``refractory_depth`` takes per pixel.
        up, ucell, upol = np.uint64(pixel), np.uint64(cell), np.uint64(polarity)  # unsigned: no negative-index fix-ups
        held = np.int64(hold[up, upol])
        age = t - surface[upol, ucell]
        if held == 0:
            at_x, at_y = _velocity_term_at(x, y, pixel, per_pixel, pinhole, sample_of, points, velocity, j, fx, fy, cx,
                                           cy)
            # age < refractory_depth / |A t| (µs, whole) without a root or a division, which would stand
            # between the hold's load and this unpredictable branch: age + 1 <= D / |A t| squared
            speed2 = at_x * at_x + at_y * at_y
            after = float(age + 1)
            burst = age < refractory_us or (refractory_reach > 0.0 and speed2 > 0.0 and (
                after <= 0.0 or after * after * speed2 <= refractory_reach * refractory_reach))
        else:
            burst = age < held
        if burst:
            counts[BURST] += 1
            continue
        surface[upol, ucell] = t
        if held != 0:
            at_x, at_y = _velocity_term_at(x, y, pixel, per_pixel, pinhole, sample_of, points, velocity, j, fx, fy, cx,
                                           cy)
            speed2 = at_x * at_x + at_y * at_y
        speed = math.sqrt(speed2)
        if speed <= 0.0:
            counts[NO_MOTION] += 1
            continue
        fu, fv = at_x / speed, at_y / speed
        at_cell = polarity * plane_size + cell  # in the flat surface: no view of the plane (a refcount per event)
        # An edge crossed the two pixels just behind this one along the motion, each about a
        # crossing time per pixel ago; in noise they fired at unrelated times. Their ages also
        # give the edge's own time per pixel, which bounds the window (``window_px``).
        supported = True
        if behind_reach > 0.0 or window_px > 0.0:
            # round(f) and round(2 f) per axis from A t's squares: no root or division on the way to the
            # unpredictable branch on ``supported``
            du1, du2 = _behind(at_x, speed2)
            dv1, dv2 = _behind(at_y, speed2)
            age1 = t - flat_surface[np.uint64(at_cell - dv1 * row - du1)]
            age2 = t - flat_surface[np.uint64(at_cell - dv2 * row - du2)]
            if behind_reach > 0.0:  # age <= (behind_depth / |A t|) * d, with d = (du, dv)·A t / |A t| px behind
                supported = (float(age1) * speed2 <= behind_reach * (du1 * at_x + dv1 * at_y)
                             and float(age2) * speed2 <= behind_reach * (du2 * at_x + dv2 * at_y))
        if not supported and not record_rejected:  # nothing to fit, nothing to record
            counts[NOTHING_BEHIND] += 1
            continue
        if not supported:
            fit, tau_s, tau_w, c, kept, rms = FIT_TOO_FEW, 0.0, 0.0, 0.0, 0, 0.0
            slot = NOTHING_BEHIND
        else:
            # 2. Gather the recent first events of the pixels the edge has crossed: at most
            # ``ahead_px`` along the motion (the pixels ahead still hold an older edge's times).
            window = window_us  # the time a surface at ``window_depth`` takes to move ``radius`` pixels
            if window_depth > 0.0:
                window = max(window, np.int64(math.floor(window_depth * radius / speed * 1e6)))
            if turn > 0.0:  # nothing from before the camera's last turn: another motion made it
                window = min(window, t - np.int64(motion[M_SINCE]))
            if window_px > 0.0:  # window_px crossings at the edge's pace (µs), without a branch
                d1, d2 = du1 * fu + dv1 * fv, du2 * fu + dv2 * fv  # their distances behind along the motion, px
                local = window_px * max(age1 / d1, age2 / d2)
                window = np.int64(math.ceil(min(local, float(window))))
            n = gather(flat_surface, at_cell, row, radius, t, window, fu, fv, ahead_px, middle, ps_, pw, pt, pg)
            if n < min_points and not record_rejected:  # fewer points than a fit keeps: too few, whatever the fit
                counts[TOO_FEW_POINTS] += 1
                continue
            # 3. Fit and check.
            if rows_model:
                fit, tau_s, tau_w, c, kept, rms = fit_rows(ps_, pt, pg, n, min_points, min_spread, outlier_px,
                                                            iterations, lines, used, give_up_rms)
            else:
                fit, tau_s, tau_w, c, kept, rms = fit_plane(ps_, pw, pt, n, min_points, min_spread, outlier_px,
                                                            iterations)
                if trim_px > 0.0 and fit == 0:
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
                        fit, tau_s, tau_w, c, kept, rms = fit_plane(ps_, pw, pt, m, min_points, min_spread, outlier_px,
                                                                    iterations)
            slot = (TOO_FEW_POINTS if fit == FIT_TOO_FEW else ILL_CONDITIONED if fit == FIT_ILL_CONDITIONED
                    else BAD_FIT if fit == FIT_OVER_RMS else EMITTED)
        a, b = tau_s * fu - tau_w * fv, tau_s * fv + tau_w * fu  # ∇T at the event, µs/px along u and v
        if slot == EMITTED and hold_px > 0.0 and rms <= hold_rms:
            # this edge's burst lasts about its ramp's width: hold_px pixels (a fit far off the
            # points, e.g. in noise, measured no crossing time: it leaves the hold as it was)
            hold[up, upol] = min(max_hold, np.int64(hold_px * math.sqrt(a * a + b * b)) + 1)
        if slot == EMITTED and rms > max_rms:
            slot = BAD_FIT
        z = 0.0
        gx, gy = a * 1e-6, b * 1e-6  # s/px
        if slot == EMITTED:
            z = at_x * gx + at_y * gy
            if rotation:
                bw_x, bw_y = rotational_flow(velocity[j, 3], velocity[j, 4], velocity[j, 5], float(x), float(y),
                                             fp[F_RFX], fp[F_RFY], fp[F_RCX], fp[F_RCY])
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
        if slot == EMITTED:  # one estimate per pixel and step, as a depth neuron: the first
            if last_step[up] == step:
                slot = SAME_STEP
            else:
                last_step[up] = step
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
