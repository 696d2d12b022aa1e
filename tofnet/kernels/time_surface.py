"""Depth from the local slope of the time surface (beyond the paper; docs/time_surface.md).

The numba core of the time-surface estimator; the streaming API and the parameters are in
``tofnet.kernels.time_surface_estimator``. Per pixel and polarity the state holds the time
(µs) of the last *first event* of an edge: the surface ``T(u, v)``. Per event: the
first-event rule (``time_surface_first``: a burst's later events are dropped), gather the first events the edge
has crossed, fit the time along the image motion (``fit_rows`` or ``fit_plane``), check the
fit, and ``Z = (A t)·∇T`` (``∇T`` s/px, the depth neuron's ``td``), or eq. 7 with a
rotation. With ``I_TRAVEL`` (``coordinates="travel"``, the default) the fit takes the camera's
travel along the image motion at the points' times instead of the times
(``tofnet.kernels.time_surface_travel``): straight when the speed changes, its slope the depth.
Each step and its parameters: docs/time_surface.md, "1. Method". Every event ends in exactly
one count slot (``COUNT_NAMES``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tofnet.kernels.cache_hints import prefetch
from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.time_surface_first import (B_EMITTED, B_HOLD, B_INDEX, N_B, N_B_LAYERED, NEVER, first_event,
                                              later_event)
from tofnet.kernels.time_surface_fit import FIT_ILL_CONDITIONED, FIT_OVER_RMS, FIT_TOO_FEW, fit_plane, fit_rows
from tofnet.kernels.time_surface_motion import (M_SINCE, M_UPDATE, M_VX, M_VY, M_VZ, N_MOTION,  # noqa: F401
                                                _gains, _turn_gains, _velocity_term_at, follow_motion)
from tofnet.kernels.time_surface_gather import behind_steps, expand, gather, time_window, trimmed_plane
from tofnet.kernels.time_surface_travel import (RING, S_CHANGE, S_FIRST, advance, pace, since_reversal, to_travel,
                                                travel_at)


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
 I_TRAVEL, I_ROW0, I_ROWS, I_OWN0, I_OWN1, I_BURST_FIT, N_IP) = range(24)
(F_FX, F_FY, F_CX, F_CY, F_OUTLIER, F_MAX_RMS, F_MIN_SPREAD, F_MIN_DEPTH, F_MAX_DEPTH, F_MIN_DENOMINATOR,
 F_WINDOW_DEPTH, F_REFRACTORY_REACH, F_CONSISTENCY, F_HOLD_PX, F_AHEAD_PX, F_TURN, F_TRIM_PX,
 F_RFX, F_RFY, F_RCX, F_RCY, F_HOLD_RMS, F_BEHIND_REACH, F_WINDOW_PX, F_BURST_RATIO, F_COS_TURN,
 N_FP) = range(27)  # F_R*: B ω's intrinsics
# F_*_REACH: a depth (m) times 1e6 µs/s; over |A t| (px m/s) it is the time (µs) per pixel of a surface that deep.
# Fit models (``I_MODEL``): a plane, or lines along the motion with a shared slope.
MODEL_PLANE, MODEL_ROWS = range(2)
MODELS = ("plane", "rows")
# Which later events of a burst are fitted on their burst-index surface (``I_BURST_FIT``): all, only those
# whose edge's first event was fitted (it passed the pixel's hold), or only those whose first event was emitted.
BURST_FIT_ALL, BURST_FIT_FITTED, BURST_FIT_EMITTED = range(3)
BURST_FITS = ("all", "fitted", "emitted")
# Status of a call.
OK, UNSORTED, NO_VELOCITY = range(3)
#: Events between a prefetch of a pixel's state and surface rows and their use.
PREFETCH = 8


# no reference counts (``_nrt``): numba counted one on each scratch array the inlined gather takes (5 atomic
# increments and decrements per gather); the kernel allocates nothing, and its arrays are all the caller's
@njit(cache=True, nogil=True, _nrt=False)  # bands run in threads (tofnet.backends.bands)
def process(ts, xs, ys, ps, ip, fp, surface, bursts, prev, last_step, motion, ring, ring_state, sample_of,
            points, velocity, first_update, ps_, pw, pt, pg, lines, used, counts, out, quality, n_out, index0, t_hi):
    """Run time-ordered events through the estimator; returns ``(n_out, status, t_hi)``.

    ``surface[p, (y + r) * (w + 2r) + x + r]`` is the last first event (µs) of pixel (x, y) and
    polarity p (one plane per polarity, so a fit reads one cache line per row; a border of
    ``r = radius`` pixels stays ``NEVER``); with burst-index surfaces (``surface`` [K, 2, plane]) ``surface[k, p]``
    holds the pixel's last event of index k in its edge's burst, and an event of index 0 < k < K is fitted on
    it as a first event is on ``surface[0, p]`` (``I_BURST_FIT``: which are; ``later_event``);
    ``bursts[y * w + x, p]`` the first-event rule's state
    (``time_surface_first``), with the measured hold (``B_HOLD`` µs, 0 = none yet) in the same row
    (with K > 1 rows of ``N_B_LAYERED`` words, the burst index ``B_INDEX`` in them);
    ``prev[y * w + x]`` the pixel's last estimate (z, t) for the consistency rule;
    ``last_step[y * w + x]`` the output step of its last estimate (at most one per pixel and step);
    ``ring`` the camera's displacement per input step and ``ring_state`` (``time_surface_travel``, with ``I_TRAVEL``).
    ``A t`` of pixel ``(x, y)`` is taken at the pixel (``I_PER_PIXEL``) or at
    ``points[sample_of[y * w + x]]``, computed only for events that need it (a pixel's first
    hold, first events). ``velocity[j - first_update]`` is (tx, ty, tz[, wx, wy, wz]) of update j.
    ``ps_``, ``pw``, ``pt``, ``pg``, ``lines``, ``used`` are the fits' scratch. The state holds the
    rows ``ip[I_ROW0] ..`` (``ip[I_ROWS]`` of them; ``y`` above is counted from the first): the
    sensor, or a band of rows plus ``radius`` either side; events of other rows only move the clock
    (a band is fed only each step's first of them: ``kernels.bands.clocked_columns``), and only
    those of rows ``ip[I_OWN0] .. ip[I_OWN1]`` are counted and fitted (a halo row's make its surface). Estimates go to
    ``out[n_out:]`` (``DEPTH_DTYPE``) and ``quality[n_out:]``. ``t_hi`` is the latest time seen
    before; an earlier event stops the call with ``UNSORTED`` before it changes any state
    (``n_out`` and ``counts`` cover the events before it).
    """
    width, height, radius = ip[I_WIDTH], ip[I_HEIGHT], ip[I_RADIUS]
    row0, rows, own0, own1 = ip[I_ROW0], np.uint64(ip[I_ROWS]), ip[I_OWN0], ip[I_OWN1]
    t0, dt, latency, update_every = ip[I_T0], ip[I_DT], ip[I_LATENCY], ip[I_UPDATE_EVERY]
    min_points, iterations = ip[I_MIN_POINTS], ip[I_ITERATIONS]
    refractory_us, window_us = ip[I_REFRACTORY], ip[I_WINDOW]
    consistency_us, max_hold, record_rejected = ip[I_CONSISTENCY_WINDOW], ip[I_MAX_HOLD], ip[I_RECORD_REJECTED] != 0
    rows_model, per_pixel, pinhole = ip[I_MODEL] == MODEL_ROWS, ip[I_PER_PIXEL] != 0, ip[I_PINHOLE] != 0
    rotation = velocity.shape[1] >= 6
    travel = ip[I_TRAVEL] != 0
    rfx, rfy, rcx, rcy = fp[F_RFX], fp[F_RFY], fp[F_RCX], fp[F_RCY]
    span_us = (RING - 2) * dt  # the oldest time the travel ring still covers
    inverse_dt = 1.0 / dt
    fx, fy, cx, cy = fp[F_FX], fp[F_FY], fp[F_CX], fp[F_CY]
    outlier_px, max_rms, min_spread = fp[F_OUTLIER], fp[F_MAX_RMS], fp[F_MIN_SPREAD]
    min_depth, max_depth, min_denominator = fp[F_MIN_DEPTH], fp[F_MAX_DEPTH], fp[F_MIN_DENOMINATOR]
    window_depth, refractory_reach, consistency = fp[F_WINDOW_DEPTH], fp[F_REFRACTORY_REACH], fp[F_CONSISTENCY]
    hold_px, ahead_px, turn, trim_px = fp[F_HOLD_PX], fp[F_AHEAD_PX], fp[F_TURN], fp[F_TRIM_PX]
    hold_rms, behind_reach, window_px = fp[F_HOLD_RMS], fp[F_BEHIND_REACH], fp[F_WINDOW_PX]
    burst_ratio, cos_turn = fp[F_BURST_RATIO], fp[F_COS_TURN]
    # burst-index surfaces: ``surface`` [K, 2, plane] (a type of its own, so numba compiles the kernel apart for
    # it: without them the dead branches below fold away and the loop's machine code is the one-surface kernel's)
    layered = surface.ndim == 3
    planes = np.int64(surface.shape[0]) if layered else np.int64(1)
    row_words = np.int64(N_B_LAYERED if layered else N_B)  # a pixel and polarity's row of the first-event rule
    behind_depth = behind_reach * 1e-6  # m: travel coordinates compare travel (px·m) with it
    # a fit this far off its points is rejected (bad_fit) and sets no hold: unless it is recorded, the fit may stop
    give_up_rms = math.inf if record_rejected else max(max_rms, hold_rms) if hold_px > 0.0 else max_rms
    row = width + 2 * radius
    middle = (lines.shape[0] - 1) // 2
    step, step_start, step_end, update, k = np.int64(0), np.int64(1), np.int64(0), np.int64(0), np.int64(0)
    linear_from = np.int64(0)
    j = 0
    tx = ty = tz = 0.0  # the step's velocity row (read per step, not per event)
    n_events, plane_size = ts.shape[0], surface.shape[surface.ndim - 1]
    flat_surface = surface.reshape(-1)
    flat_points, points_columns = points.reshape(-1), points.shape[1]
    flat_bursts = bursts.reshape(-1)
    for i in range(n_events):
        if i + PREFETCH < n_events:  # what a first event would read: the rows of its square, its A t's sample
            # clamped into the rows held, not tested: in a band, whether an event is its own is a coin toss
            xq = min(np.int64(xs[i + PREFETCH]), width - 1)
            yq = min(max(np.int64(ys[i + PREFETCH]) - row0, 0), np.int64(rows) - 1)
            pq = 1 if ps[i + PREFETCH] != 0 else 0
            prefetch(flat_bursts, row_words * (2 * (yq * width + xq) + pq))
            top = pq * plane_size + yq * row + xq + radius  # the square's first row
            if radius == 3:  # the default, unrolled: a counter and a branch per row were most of this block
                for dq in range(7):
                    prefetch(flat_surface, top + dq * row)
            else:
                for dq in range(2 * radius + 1):
                    prefetch(flat_surface, top + dq * row)
            if layered:  # a burst's later event writes its cell on the surface of its index (k < K)
                own = top + radius * row
                for kq in range(1, planes):
                    prefetch(flat_surface, own + 2 * kq * plane_size)
            if not pinhole:
                sq = (yq + row0) * width + xq
                sq = sq if per_pixel else sample_of[sq]
                prefetch(flat_points, sq * points_columns)
                prefetch(flat_points, sq * points_columns + points_columns - 1)
        t = ts[i]
        if t < t_hi:
            return n_out, UNSORTED, t_hi
        t_hi = t
        x, y = np.int64(xs[i]), np.int64(ys[i])
        mine = own0 <= y < own1  # a band counts and fits the events of its own rows (past the sensor: the last)
        if x >= width or y >= height:
            counts[OUT_OF_BOUNDS] += mine
            continue
        if t < t0:
            counts[BEFORE_T0] += mine
            continue
        if t >= step_end or t < step_start:  # divisions only when the step changes
            k = (t - t0) // dt
            step_start, step_end = t0 + k * dt, t0 + (k + 1) * dt
            step = k + latency  # the output step; it holds update (step - 1) // U (docs/semantics.md)
            update = (step - 1) // update_every
            j = update - first_update
            if j < 0 or j >= velocity.shape[0]:
                return n_out, NO_VELOCITY, t_hi
            tx, ty, tz = velocity[j, 0], velocity[j, 1], velocity[j, 2]
            if update != motion[M_UPDATE]:
                follow_motion(motion, velocity[j], update, t0 + update * update_every * dt, turn)
            if travel:
                advance(ring, ring_state, k, velocity[j], dt * 1e-6)
                # since then the travel is |A t| times the time (no change since the first step: always)
                linear_from = t0 + ring_state[S_CHANGE] * dt if ring_state[S_CHANGE] != ring_state[S_FIRST] else NEVER
        if np.uint64(y - row0) >= rows:  # another band's row (its steps still move the travel ring, above)
            continue
        polarity = 1 if ps[i] != 0 else 0
        sample = y * width + x  # in the sensor's tables; the state holds rows row0 .. row0 + rows
        pixel = (y - row0) * width + x
        cell = (y - row0 + radius) * row + x + radius
        # 1. First-event rule (``time_surface_first``): the surface takes the events that start an edge, from
        # the pixel's own events and A t alone; an event is fitted once the pixel's hold has passed (within a
        # burst, with its edge's start as its own point).
        up = np.uint64(pixel)  # unsigned: no negative-index fix-ups
        at_x, at_y = _velocity_term_at(x, y, sample, per_pixel, pinhole, sample_of, points, tx, ty, tz, fx, fy, cx,
                                       cy)
        speed2 = at_x * at_x + at_y * at_y
        at_cell = polarity * plane_size + cell  # in the flat surface: no view of the plane (a refcount per event)
        state = row_words * (2 * pixel + polarity)
        edge, fitted = first_event(flat_bursts, state, t, burst_ratio, refractory_us, refractory_reach, speed2)
        if layered:  # a burst's later event k < K writes surface k and is fitted there, as a first event on 0
            at_cell, edge, fitted = later_event(flat_bursts, flat_surface, state, at_cell, plane_size, edge, fitted,
                                                planes, ip[I_BURST_FIT])
        flat_surface[np.uint64(at_cell)] = t if edge else flat_surface[np.uint64(at_cell)]
        if not mine:  # a halo row: its surface only, for the band's fits
            continue
        if not fitted:
            counts[BURST] += 1
            continue
        speed = math.sqrt(speed2)
        if speed <= 0.0:
            counts[NO_MOTION] += 1
            continue
        fu, fv = at_x / speed, at_y / speed
        # A burst's later event where its pixel already emitted in this step would end ``same_step`` whatever its
        # fit, which sets no hold: not fitted (on edges that fire twice per crossing, most of the later events)
        repeat = layered and at_cell >= 2 * plane_size and last_step[up] == step
        if repeat and not record_rejected:
            counts[SAME_STEP] += 1
            continue
        # An edge crossed the two pixels just behind this one along the motion, each about a
        # crossing time per pixel ago; in noise they fired at unrelated times. Their ages also
        # give the edge's own time per pixel, which bounds the window (``window_px``).
        supported, linear, fitted_z = True, False, math.nan
        if behind_depth > 0.0 or window_px > 0.0 or travel:
            # round(f) and round(2 f) per axis from A t's squares: no root or division on the way to the
            # unpredictable branch on ``supported``
            du1, du2 = behind_steps(at_x, speed2)
            dv1, dv2 = behind_steps(at_y, speed2)
            age1 = t - flat_surface[np.uint64(at_cell - dv1 * row - du1)]
            age2 = t - flat_surface[np.uint64(at_cell - dv2 * row - du2)]
            if travel:  # the same in travel (px·m): a surface at D travels D per pixel, whatever the speed
                d1, d2 = du1 * fu + dv1 * fv, du2 * fu + dv2 * fv  # their distances behind along the motion, px
                rate = speed * 1e-6  # px·m per µs while the velocity has not changed
                h0 = h1 = h2 = turn_rate = 0.0
                if rotation:  # where the edge was, net of the rotation's image motion (px along f)
                    h0, h1, h2 = _turn_gains(x, y, fu, fv, rfx, rfy, rcx, rcy)
                    turn_rate = h0 * velocity[j, 3] + h1 * velocity[j, 4] + h2 * velocity[j, 5]  # px/s
                # as in time while nothing changed; with a rotation always in travel, net of its image motion
                if not rotation and t - max(age1, age2) >= linear_from:
                    travel1, travel2 = rate * age1, rate * age2
                else:
                    g0, g1, g2 = _gains(x, y, sample, per_pixel, pinhole, sample_of, points, fu, fv, fx, fy, cx, cy)
                    here, turned = travel_at(ring, t, t0, dt, inverse_dt, g0, g1, g2, h0, h1, h2)
                    travel1, turned1 = travel_at(ring, t - age1, t0, dt, inverse_dt, g0, g1, g2, h0, h1, h2)
                    travel2, turned2 = travel_at(ring, t - age2, t0, dt, inverse_dt, g0, g1, g2, h0, h1, h2)
                    travel1, travel2 = here - travel1, here - travel2
                    d1, d2 = d1 - (turned - turned1), d2 - (turned - turned2)
                    travel1 = travel1 if age1 <= span_us else math.inf  # older than the ring: no measure
                    travel2 = travel2 if age2 <= span_us else math.inf
                if behind_depth > 0.0:  # (negative: they fired before the motion along f reversed)
                    # one branch on the outcome, not one per comparison (noise makes each a coin toss)
                    supported = ((travel1 >= 0.0) & (travel1 <= behind_depth * d1) & (travel2 >= 0.0)
                                 & (travel2 <= behind_depth * d2))
            elif behind_reach > 0.0:  # age <= (behind_depth / |A t|) * d, with d = (du, dv)·A t / |A t| px behind
                supported = (float(age1) * speed2 <= behind_reach * (du1 * at_x + dv1 * at_y)
                             and float(age2) * speed2 <= behind_reach * (du2 * at_x + dv2 * at_y))
        if not supported and not record_rejected:  # nothing to fit, nothing to record
            counts[NOTHING_BEHIND] += 1
            continue
        if repeat or not supported:
            fit, tau_s, tau_w, c, kept, rms = FIT_TOO_FEW, 0.0, 0.0, 0.0, 0, 0.0
            slot = SAME_STEP if repeat else NOTHING_BEHIND
        else:
            # 2. Gather the recent first events of the pixels the edge has crossed: at most
            # ``ahead_px`` along the motion (the pixels ahead still hold an older edge's times).
            # the rows fit's slope across the motion within its lines (``fit_rows``): where the lines' w are not
            # whole pixels (along an axis they are). In time not with a rotation: where its image motion runs across
            # f the lines along f are not the edges' tracks (pan: docs/time_surface.md 7d); in travel coordinates
            # the points' positions are net of it (``to_travel``), and the lines follow the tracks
            slanted = abs(fu) > 1e-6 and abs(fv) > 1e-6 and not (rotation and not travel)
            if travel:
                # the travel a surface at ``window_depth`` makes over ``radius`` px, nor more than ``window_px``
                # crossings at the edge's pace; in time, back to where the image motion along f reversed
                reach = window_depth * radius if window_depth > 0.0 else math.inf
                suggested = max(pace(travel1, d1), pace(travel2, d2))  # the depth the pixels behind suggest
                # with a rotation ``reach`` is the depth times the image motion, z_guess that depth
                z_guess = suggested if suggested < math.inf else window_depth
                if window_px > 0.0:
                    reach = min(reach, window_px * suggested)
                # all of it since the last change: time will do (not with a rotation: there the points' positions
                # are taken net of its image motion, across f too, which the ring gives)
                linear = not rotation and reach < rate * (t - linear_from)
                if linear:
                    window = np.int64(math.floor(reach / rate))
                    n = gather(flat_surface, at_cell, row, radius, t, window, fu, fv, ahead_px, middle, ps_, pw, pt,
                               pg)
                    expand(ps_, pt, n, tz / speed)  # each point's own image speed (``to_travel`` takes it below)
                else:
                    g0, g1, g2 = _gains(x, y, sample, per_pixel, pinhole, sample_of, points, fu, fv, fx, fy, cx, cy)
                    # Aᵀf⊥ and Bᵀf⊥ (f⊥ = (-fv, fu)): the image motion across f. The window stops once the
                    # translation's turned by max_turn; the points' positions across are taken net of both
                    q0, q1, q2 = _gains(x, y, sample, per_pixel, pinhole, sample_of, points, -fv, fu, fx, fy, cx, cy)
                    k0 = k1 = k2 = 0.0
                    if rotation:
                        k0, k1, k2 = _turn_gains(x, y, -fv, fu, rfx, rfy, rcx, rcy)
                    window = since_reversal(ring, k, t, t0, dt, np.int64(ring_state[S_FIRST]), g0, g1, g2,
                                            z_guess * h0, z_guess * h1, z_guess * h2, reach, q0, q1, q2, cos_turn)
                    n = gather(flat_surface, at_cell, row, radius, t, window, fu, fv, ahead_px, middle, ps_, pw, pt,
                               pg)
                    n = to_travel(ring, ps_, pw, pt, pg, n, t, t0, dt, g0, g1, g2, h0, h1, h2, z_guess, reach, q0, q1,
                                  q2, k0, k1, k2, middle)
                    slanted = True  # net of the motion since, the points' w are not whole pixels
            else:
                window = time_window(window_us, window_depth, radius, speed, turn, t, motion[M_SINCE], window_px,
                                      du1, dv1, du2, dv2, fu, fv, age1, age2)
                n = gather(flat_surface, at_cell, row, radius, t, window, fu, fv, ahead_px, middle, ps_, pw, pt, pg)
                expand(ps_, pt, n, 0.0 if rotation else tz / speed)
            if n < min_points and not record_rejected:  # fewer points than a fit keeps: too few, whatever the fit
                counts[TOO_FEW_POINTS] += 1
                continue
            # 3. Fit and check. Net of a rotation, a point's position is the translation's share of the image
            # motion: the limits in image pixels are that share of them there
            share = 1.0
            if travel and rotation and speed + z_guess * turn_rate > 0.0:
                share = speed / (speed + z_guess * turn_rate)
            # with a rotation a point's timing error moves its travel and its position net of the rotation
            # together: the rows fit takes the slope with what that error leaves alone (docs/time_surface.md, 7i)
            instrument = turn_rate / speed if travel and rotation else 0.0
            if rows_model:
                fit, tau_s, tau_w, c, kept, rms = fit_rows(ps_, pw, pt, pg, n, min_points, min_spread * share * share,
                                                            outlier_px * share, iterations, lines, used,
                                                            give_up_rms * share, slanted, instrument)
            else:
                fit, tau_s, tau_w, c, kept, rms = fit_plane(ps_, pw, pt, n, min_points, min_spread * share * share,
                                                            outlier_px * share, iterations)
            if share != 1.0:
                rms /= share
            if not rows_model and trim_px > 0.0 and fit == 0:
                fit, tau_s, tau_w, c, kept, rms = trimmed_plane(ps_, pw, pt, window, trim_px, fit, tau_s, tau_w, c,
                                                                kept, rms, min_points, min_spread, outlier_px,
                                                                iterations)
            if travel and not linear:  # the slope is the depth; to µs per px at the event's image speed
                fitted_z = tau_s
                image_rate = speed + tau_s * turn_rate  # px·m/s: Z times the image speed along f
                scale = 1e6 / image_rate if image_rate > 0.0 else 0.0
                tau_s, tau_w = tau_s * scale, tau_w * scale
            slot = (TOO_FEW_POINTS if fit == FIT_TOO_FEW else ILL_CONDITIONED if fit == FIT_ILL_CONDITIONED
                    else BAD_FIT if fit == FIT_OVER_RMS else EMITTED)
        a, b = tau_s * fu - tau_w * fv, tau_s * fv + tau_w * fu  # ∇T at the event, µs/px along u and v
        if slot == EMITTED and hold_px > 0.0 and rms <= hold_rms and (not layered or at_cell < 2 * plane_size):
            # this edge's burst lasts about its ramp's width: hold_px pixels (a fit far off the
            # points, e.g. in noise, measured no crossing time: it leaves the hold as it was)
            flat_bursts[np.uint64(state + B_HOLD)] = min(max_hold, np.int64(hold_px * math.sqrt(a * a + b * b)) + 1)
        if slot == EMITTED and rms > max_rms:
            slot = BAD_FIT
        z = 0.0
        gx, gy = a * 1e-6, b * 1e-6  # s/px
        if slot == EMITTED and fitted_z == fitted_z:  # a travel fit: its slope is the depth, rotation included
            z = fitted_z
            image_rate = speed + z * turn_rate  # the translation's share of it is speed / image_rate
            if rotation and (image_rate <= 0.0 or speed < min_denominator * image_rate):
                slot = ROTATION_DOMINATED
        elif slot == EMITTED:
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
                if layered and at_cell < 2 * plane_size:  # a first event: its burst may ask (``later_event``)
                    flat_bursts[np.uint64(state + B_INDEX)] = B_EMITTED
        counts[slot] += 1
        if slot != EMITTED:
            if not record_rejected:
                continue
            z = math.nan
        estimate, q = out[np.uint64(n_out)], quality[np.uint64(n_out)]
        estimate.t, estimate.x, estimate.y, estimate.z, estimate.step = step_end + latency * dt, x, y, z, step
        q.t_event, q.points, q.rms_px, q.gx, q.gy, q.index, q.reason = t, kept, rms, gx, gy, index0 + i, slot
        q.burst = at_cell // (2 * plane_size) if layered else 0  # the burst index k: its surface
        n_out += 1
    return n_out, OK, t_hi
