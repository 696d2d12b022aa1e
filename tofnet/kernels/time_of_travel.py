"""Event-driven time-of-travel layer and depth neuron (numba core; the API is ``tofnet.kernels.region``).

Implements docs/semantics.md ("Time-of-travel units", "Depth neuron") with work
proportional to events, not pixels x steps: a unit stores the step ``a`` of its last
facilitation and that spike's polarity instead of a counter (``counter = now - a``).
``process`` takes accepted spikes (input step, x, y, polarity), or raw events (t µs, x, y,
polarity; ``process_events``) that it runs through ``input_filter.admit`` in the same pass
("fused"); a packet of raw events out of time order is refused before any state changes
(``UNSORTED``) and ``region`` runs it unfused. Facilitations wait in ``pend`` until a
later step's spike arrives, so packets may be split anywhere. The state layout (stamps,
rebase, one cache line per pixel), the branch-free event path and the prefetching, with
the measurements behind them: docs/performance.md, "How the kernel is built".
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tofnet.kernels.cache_hints import prefetch
from tofnet.kernels.depth import float_depth
from tofnet.kernels.fixed_point import fixed_depth, quantize
from tofnet.kernels.input_filter import ACCEPTED, BEFORE_T0, OUT_OF_BOUNDS, admit
from tofnet.kernels.kernel_config import COLUMNS
from tofnet.kernels.lens import SAMPLE_COLUMNS
from tofnet.kernels.order import sort_by_pixel
from tofnet.kernels.velocity import sampled_velocity_term

#: Stamp of an idle unit (never facilitated, sent since, or overflowed at a rebase).
IDLE = -(1 << 31)
#: Rebase when ``now - base`` exceeds this, keeping ``key`` below 2**31.
REBASE_AFTER = (1 << 30) - 4
#: int64 words per pixel record: 4 stamps + filter time (32 B), or + 3 filter times (64 B).
WORDS, WORDS_PER_POLARITY = 4, 8
FILTER_WORD = 2
#: Events (or pending facilitations) between a prefetch and its use.
PREFETCH = 12
# Status codes.
OK, UNSORTED, PENDING_FULL, NO_VELOCITY = 0, 1, 2, 3
# Cursor slots: buffered facilitations, current input step, stamp base, latest event time
# seen by the fused path, and the step range a call needs velocities for (NO_VELOCITY).
N_PEND, CURRENT, BASE, T_HI, NEED_FIRST, NEED_LAST = range(6)
N_CURSOR = 6
# Count slots: input_filter's drop reasons and ACCEPTED (0-4), depth outcomes (5-10:
# the N_REASONS rejection reasons ``DepthProcess.counters`` declares, emitted, no unit fired), time-of-travel spikes. The
# fused kernel computes eq. 8 only, so it never counts ``rotation_dominated`` (slot 8).
# ``HALO``: where the filter's outcomes for a halo pixel go (a band's halo pixel belongs to
# another band, which counts it), so a banded run counts every event once.
N_REASONS = 4
REJECTED = 5
EMITTED = REJECTED + N_REASONS
INACTIVE, TOT_SPIKES, HALO, N_COUNTS = EMITTED + 1, EMITTED + 2, EMITTED + 3, EMITTED + 4
# The state travels in two arrays (each array argument costs ~0.1 µs per call): ``ints``
# holds the integer parameters ``ip`` (these slots), then at the offsets they give the
# cursor, the counts, the sample tables, the caches, the facilitation buffer and the
# pixel records; ``floats`` holds the float parameters, the sample points and ``A t``.
(X0, Y0, X1, Y1, DISTANCE, COUNTER_MAX, REBASE_AT, UPDATE_EVERY, FIXED, FRAC_BITS, PAYLOAD_BITS, MIN_RAW,
 MAX_RAW, T0, DT, REFRACTORY_US, PER_POLARITY, WIDTH, HEIGHT, STRIDE, ROW, N_SAMPLES, EMIT_DEPTH,
 AT_CURSOR, AT_COUNTS, AT_ROWS, AT_COLS, AT_CACHE_J, AT_CACHE_W, AT_PEND, PEND_SIZE, AT_REC, REC_SIZE, N_IP) = range(34)
# Float slots, then the points (per sample: where ``A t`` is evaluated and the lens's ``J``,
# ``tofnet.kernels.lens``) and the cached ``A t`` (x, y per sample).
FX, FY, CX, CY, SECONDS_PER_COUNT, MIN_DEPTH, MAX_DEPTH, N_FP = range(8)

_BIG = 1 << 40  # above any counter value
#: A band's event positions (``index``) masked with this are known non-negative: numba then omits the
#: negative-index wrap of every array read at that position (the whole loop's ``range`` index has none).
_POSITION = (1 << 63) - 1


@njit(cache=True, inline="always")
def _unit(stamp, u, key, max_diff):
    """Trigger unit ``stamp[u]``: (counter it sends or 0, 1 if it fired); a unit that fires goes idle."""
    s = stamp[u]
    diff = key - np.int64(s)  # 2*(now - a) with the same polarity, odd otherwise
    fired = np.int64(np.uint64(diff - 2) <= np.uint64(max_diff - 2)) & ~diff & 1
    stamp[u] = np.int32(IDLE) if fired else s
    return (diff >> 1) & -fired, fired


@njit(cache=True)
def axis_count(m_positive: int, m_negative: int) -> int:
    """``depth.signed_axis_count`` without branches: the smaller of two counts (0 = none), signed; a tie is 0."""
    a = m_positive if m_positive > 0 else _BIG
    b = m_negative if m_negative > 0 else _BIG
    return np.int64(a < b) * m_positive - np.int64(b < a) * m_negative


@njit(cache=True)
def outcome(fired: int, measured: bool, z, min_depth, max_depth) -> int:
    """``depth.classify`` without branches, as a count slot offset: rejection reason index,
    N_REASONS emitted, N_REASONS + 1 no unit fired (the depth neuron received nothing)."""
    near = np.int64(z <= min_depth)
    far = np.int64(z >= max_depth) & (1 - near)
    slot = np.int64(measured) * (N_REASONS - (N_REASONS - 1) * near - (N_REASONS - 2) * far)
    return slot if fired else N_REASONS + 1


@njit(cache=True, inline="always")
def depth_params(ip, fp):
    """The depth neuron's constants, read once per call (``depth_of``'s ``params``)."""
    frac_bits = ip[FRAC_BITS]
    return (ip[FIXED] != 0, frac_bits, ip[PAYLOAD_BITS], 1.0 / (1 << frac_bits), ip[MIN_RAW], ip[MAX_RAW],
            fp[MIN_DEPTH], fp[MAX_DEPTH], fp[FX], fp[FY], fp[CX], fp[CY], fp[SECONDS_PER_COUNT])


@njit(cache=True)
def refresh_sample(sample, update, tx, ty, tz, params, cache_j, cache_w, cache_at, points):
    """``A t`` (and ``W = A t * dt / distance`` quantised, in fixed point) of one sample under
    velocity ``update``, cached: called once per sample (patch or pixel) and update."""
    fixed, frac_bits, payload_bits, _, _, _, _, _, fx, fy, cx, cy, seconds_per_count = params
    at_x, at_y = sampled_velocity_term(tx, ty, tz, points[SAMPLE_COLUMNS * sample:SAMPLE_COLUMNS * (sample + 1)],
                                       fx, fy, cx, cy)
    cache_at[2 * sample], cache_at[2 * sample + 1] = at_x, at_y
    if fixed:  # W quantised once (docs/fixed_point.md)
        cache_w[2 * sample] = quantize(at_x * seconds_per_count, frac_bits, payload_bits)
        cache_w[2 * sample + 1] = quantize(at_y * seconds_per_count, frac_bits, payload_bits)
    cache_j[sample] = update


@njit(cache=True, inline="always")
def depth_of(m0, m1, m2, m3, fired, w_x, w_y, at_x, at_y, params):
    """The depth neuron (paper eq. 8) from its four counters and its sample's cached ``W``/``A t``:
    ``(z metres, raw fixed-point z or 0, outcome slot)``. Scalars only (arrays passed to an
    inlined function cost reference counting per event). Shared by the fused kernel and the
    depth layer alone (``depth_counts``)."""
    fixed, _, payload_bits, lsb, min_raw, max_raw, min_depth, max_depth, _, _, _, _, seconds_per_count = params
    sx, sy = axis_count(m0, m1), axis_count(m2, m3)
    measured = (sx | sy) != 0
    if fixed:
        raw = fixed_depth(sx, sy, w_x, w_y, payload_bits)
        slot = outcome(fired, measured, raw, min_raw, max_raw)
        z = raw * lsb
    else:
        raw = 0
        z = float_depth(sx, sy, at_x, at_y, seconds_per_count)
        slot = outcome(fired, measured, z, min_depth, max_depth)
    return z, raw, slot


@njit(cache=True, inline="always")  # a call in the event loop makes the loop 30 % slower (docs/performance.md)
def _flush(stamp, pend, n_pend, key_base, su, sv):
    """Apply buffered facilitations ``(stamp index << 1) | polarity`` of one step (key ``key_base``)."""
    one, two, three = np.uint64(1), np.uint64(2), np.uint64(3)
    for q in range(n_pend):
        if q + PREFETCH < n_pend:
            w = np.uint64(pend[q + PREFETCH] >> 1)
            prefetch(stamp, w + su)
            prefetch(stamp, w - su)
            prefetch(stamp, w + sv)
            prefetch(stamp, w - sv)
        v = pend[q]
        key = np.int32(key_base | (v & 1))
        u = np.uint64(v >> 1)
        stamp[u + su] = key  # +u: the pixel an edge moving +u reaches next
        stamp[u - su + one] = key  # -u
        stamp[u + sv + two] = key  # +v
        stamp[u - sv + three] = key  # -v


@njit(cache=True)
def _rebase(stamp, stride, base, new_base, counter_max):
    """Re-express stamps relative to ``new_base``; units too old to ever fire become idle."""
    shift = (new_base - base) << 1
    for r in range(0, stamp.shape[0], 2 * stride):
        for c in range(4):
            s = stamp[r + c]
            if s != IDLE:
                v = np.int64(s) - shift
                stamp[r + c] = IDLE if -(v >> 1) > counter_max else v  # past the counter maximum at new_base


@njit(cache=True)
def _check(ts, xs, ys, filtering, cursor, ip, n_rows, first_update, ordered):
    """Refuse input out of order or beyond the velocity table before any state changes; returns a status.
    ``ordered``: the caller has checked that the events are in time order among themselves (a band's
    ``select_rows``); only the first is compared with the latest time fed."""
    n = ts.shape[0]
    found = False
    lo = hi = np.int64(0)
    if filtering:  # events: all in time order, also after earlier calls (T_HI: the latest time fed)
        t0, width, height = ip[T0], ip[WIDTH], ip[HEIGHT]
        if n == 0:
            return OK
        back = ts[0] < cursor[T_HI]
        if not ordered:
            for i in range(1, n):  # no early exit: a branch-free loop is several times faster
                back |= ts[i] < ts[i - 1]
        if back:
            return UNSORTED
        first = last = -1  # the first and the last event the filter may accept (scans stop early)
        for i in range(n):
            if xs[i] < width and ys[i] < height and ts[i] >= t0:
                first = i
                break
        if first >= 0:
            for i in range(n - 1, first - 1, -1):
                if xs[i] < width and ys[i] < height:  # ts[i] >= ts[first] >= t0
                    last = i
                    break
            found = True
            lo, hi = (ts[first] - t0) // ip[DT], (ts[last] - t0) // ip[DT]
    else:  # spikes: sorted by step, continuing the previous call's
        previous = max(cursor[CURRENT], 0)
        for i in range(n):
            if ts[i] < previous:
                return UNSORTED
            previous = ts[i]
        if n:
            lo, hi, found = ts[0], ts[n - 1], True
    u = ip[UPDATE_EVERY]
    if found and ip[EMIT_DEPTH] != 0 and ((lo + 1) // u < first_update or (hi + 1) // u - first_update >= n_rows):
        cursor[NEED_FIRST], cursor[NEED_LAST] = lo, hi
        return NO_VELOCITY
    return OK


@njit(cache=True)
def views(ints, floats):
    """The parts of the packed state (see the layout above), as views."""
    ip = ints[:N_IP]
    n_samples = ip[N_SAMPLES]
    rec = ints[ip[AT_REC]:ip[AT_REC] + ip[REC_SIZE]]
    return (ip, ints[ip[AT_CURSOR]:ip[AT_CURSOR] + N_CURSOR], ints[ip[AT_COUNTS]:ip[AT_COUNTS] + N_COUNTS],
            ints[ip[AT_ROWS]:ip[AT_COLS]], ints[ip[AT_COLS]:ip[AT_CACHE_J]],
            ints[ip[AT_CACHE_J]:ip[AT_CACHE_J] + n_samples], ints[ip[AT_CACHE_W]:ip[AT_CACHE_W] + 2 * n_samples],
            ints[ip[AT_PEND]:ip[AT_PEND] + ip[PEND_SIZE]], rec,
            floats[:N_FP], floats[N_FP:N_FP + SAMPLE_COLUMNS * n_samples],
            floats[N_FP + SAMPLE_COLUMNS * n_samples:N_FP + (SAMPLE_COLUMNS + 2) * n_samples])


@njit(cache=True, nogil=True)  # bands run in threads (tofnet.backends.bands)
def process_events(events, ints, floats, velocity, first_update, out, out_raw, n_out, record_tot, tot, n_tot,
                   scratch, row_start, canonical, index, band):
    """Raw events (``EVENT_DTYPE``) through the input filter and the region (``process``); with
    ``canonical`` the estimates in the canonical order (``order.sort_by_pixel``, with ``scratch``
    and ``row_start``) unless their fixed-point values are kept too (``out_raw`` not empty: the
    caller sorts), else in the order their trigger events came. ``index``, ``band``: as ``process``."""
    n_out2, n_tot2, status = process(events["t"], events["x"], events["y"], events["p"], True, ints, floats,
                                     velocity, first_update, out, out_raw, n_out, record_tot, tot, n_tot, index, band)
    if canonical and status == OK and out_raw.shape[0] == 0 and n_out2 - n_out > 1:
        sort_by_pixel(out, n_out, n_out2, ints[HEIGHT], scratch, row_start)
    return n_out2, n_tot2, status


@njit(cache=True, nogil=True)
def process(ts, xs, ys, ps, filtering, ints, floats, velocity, first_update, out, out_raw, n_out, record_tot, tot,
            n_tot, index, band):
    """Run a packet through the region; returns ``(n_out, n_tot, status)``.

    ``filtering``: ``ts`` are event times (µs) and the input filter runs first (on the
    region's halo; only the region's own pixels' outcomes count, the halo's go to ``HALO``); else ``ts`` are input steps of accepted spikes. Depth estimates are
    written to ``out[n_out:]`` (``DEPTH_DTYPE``, capacity ``n_out + len(ts)``) and their
    fixed-point values to ``out_raw`` unless it is empty; time-of-travel spikes to ``tot``
    (from ``n_tot`` on) when ``record_tot``. The sample of pixel (x, y) is
    ``rows[y - y0] + cols[x - x0]``: an index into the points (where ``A t`` is evaluated);
    ``A t`` and ``W`` are cached per sample and velocity update (``cache_j``).
    ``velocity[j - first_update]`` is the velocity of update ``j``. ``index`` (None: all events):
    only the events at these positions (increasing) run, a band's (``tofnet.backends.bands``); the caller
    has checked the events' time order among themselves over all of them (``kernels.bands.select_rows``,
    so every band refuses the same packets); the first is still compared with the latest time fed.
    ``band`` None: the region is the whole sensor, every event on it is the region's own; else
    the region's ``Region.kinds`` (a part of the sensor: a band's, a core's). None compiles the whole
    sensor's loop without a band's per-event region and halo checks.
    """
    ip, cursor, counts, rows, cols, cache_j, cache_w, pend, rec, fp, points, cache_at = views(ints, floats)
    stamp = rec.view(np.int32)
    status = _check(ts, xs, ys, filtering, cursor, ip, velocity.shape[0], first_update, index is not None)
    if status != OK:
        return n_out, n_tot, status
    n = ts.shape[0]
    if index is not None:  # ``is None`` on an argument: numba compiles each case without the other
        n = index.shape[0]
    x0, y0, x1, y1, d = ip[X0], ip[Y0], ip[X1], ip[Y1], ip[DISTANCE]
    t0, dt, refractory, width, height = ip[T0], ip[DT], ip[REFRACTORY_US], ip[WIDTH], ip[HEIGHT]
    stride, row, update_every = ip[STRIDE], ip[ROW], ip[UPDATE_EVERY]
    per_polarity = ip[PER_POLARITY] != 0
    params = depth_params(ip, fp)
    keep_raw = out_raw.shape[0] > 0
    max_diff = 2 * ip[COUNTER_MAX]
    latest = FILTER_WORD + 2 if per_polarity else FILTER_WORD
    hx0, hy0, hx1, hy1 = x0 - d, y0 - d, x1 + d, y1 + d
    pad_x, pad_y = 2 * d - x0, 2 * d - y0
    su, sv = np.uint64(2 * stride * d), np.uint64(2 * stride * row * d)  # stamp offsets of the neighbours
    emit_depth = ip[EMIT_DEPTH] != 0
    n_pend, current, base = cursor[N_PEND], cursor[CURRENT], cursor[BASE]
    step, step_start, step_end = np.int64(0), np.int64(0), np.int64(-(1 << 62))  # filter's step
    hoisted = np.int64(-(1 << 62))  # the step whose key, velocity and stamp are below
    key_now = update = stamp_us = np.int64(0)
    tx = ty = tz = 0.0
    for e in range(n):
        i = q = e
        if index is not None:
            i = index[e] & _POSITION
        if e + PREFETCH < n:
            q = e + PREFETCH
            if index is not None:
                q = index[q] & _POSITION
            xq, yq = np.int64(xs[q]), np.int64(ys[q])
            if band is not None and filtering:  # a band's events' pixels are uint16: its table says
                if band[yq] & band[COLUMNS + xq]:
                    prefetch(rec, ((yq + pad_y) * row + xq + pad_x) * stride)
            elif hx0 <= xq < hx1 and hy0 <= yq < hy1:
                prefetch(rec, ((yq + pad_y) * row + xq + pad_x) * stride)
        x, y = np.int64(xs[i]), np.int64(ys[i])
        polarity = 1 if ps[i] != 0 else 0
        r = ((y + pad_y) * row + x + pad_x) * stride  # the pixel's record (valid inside the halo)
        # the region's own pixel: it triggers, and its events count (``band is None``: a constant, the
        # whole sensor's loop has no region or halo checks)
        kind = 3
        if band is not None:  # two loads instead of eight comparisons; events' pixels are uint16
            if filtering:
                kind = band[y] & band[COLUMNS + x]
            else:  # input spikes may carry any int64 pixel: past the table is outside the halo
                kind = band[min(np.uint64(y), np.uint64(COLUMNS - 1))] & band[
                    COLUMNS + min(np.uint64(x), np.uint64(COLUMNS - 1))]
        own = band is None or kind > 1
        halo = band is None or kind != 0  # in the region's halo (its record exists)
        if filtering:
            t = ts[i]
            if x >= width or y >= height:
                counts[OUT_OF_BOUNDS if y >= height or y0 <= y < y1 else HALO] += 1  # once over bands
                continue
            if not halo:
                continue  # a band's kernel is given its halo's events only; others have no record here
            if t < t0:
                counts[BEFORE_T0 if own else HALO] += 1
                continue
            if t >= step_end:  # events are in time order (checked): a division per step, not per event
                step = (t - t0) // dt
                step_start = t0 + step * dt
                step_end = step_start + dt
            reason = admit(rec, r + FILTER_WORD + (polarity if per_polarity else 0), r + latest,
                           t, step_start, step_end, refractory)
            counts[reason if own else HALO] += 1
            if reason != ACCEPTED:
                continue
            k = step
        else:
            k = ts[i]
        if k != hoisted:
            if k != current:  # the facilitations of step `current` are complete
                if n_pend > 0:
                    _flush(stamp, pend, n_pend, (current + 1 - base) << 1, su, sv)
                    n_pend = 0
                current = k
                if k + 1 - base > ip[REBASE_AT]:
                    _rebase(stamp, stride, base, k + 1, ip[COUNTER_MAX])
                    base = k + 1
            hoisted = k
            key_now = (k + 1 - base) << 1
            # Depth neurons of step k+2 hold update (k+1) // U (docs/semantics.md).
            if emit_depth:
                update = (k + 1) // update_every
                j = update - first_update
                tx, ty, tz = velocity[j, 0], velocity[j, 1], velocity[j, 2]
                stamp_us = t0 + (k + 3) * dt  # end of depth step k+2
        if not filtering and not halo:  # (filtering: refused above)
            continue  # neither triggers nor facilitates here
        u = np.uint64(2 * r)  # stamp of unit 0
        if own:
            # 1. Triggers, in step k+1.
            key = key_now | polarity
            m0, f0 = _unit(stamp, u, key, max_diff)
            m1, f1 = _unit(stamp, u + np.uint64(1), key, max_diff)
            m2, f2 = _unit(stamp, u + np.uint64(2), key, max_diff)
            m3, f3 = _unit(stamp, u + np.uint64(3), key, max_diff)
            fired = f0 + f1 + f2 + f3
            counts[TOT_SPIKES] += fired
            if record_tot and fired:
                for c, m in enumerate((m0, m1, m2, m3)):
                    if m > 0:
                        spike = tot[n_tot]
                        spike.step, spike.x, spike.y, spike.direction, spike.count = k + 1, x, y, c, m
                        n_tot += 1
            # 2. The pixel's depth neuron, in step k+2.
            if emit_depth:
                sample = rows[y - y0] + cols[x - x0]
                if cache_j[sample] != update:  # the first depth neuron of this sample under this update
                    refresh_sample(sample, update, tx, ty, tz, params, cache_j, cache_w, cache_at, points)
                z, raw, slot = depth_of(m0, m1, m2, m3, fired, cache_w[2 * sample], cache_w[2 * sample + 1],
                                        cache_at[2 * sample], cache_at[2 * sample + 1], params)
                counts[REJECTED + slot] += 1
                estimate = out[n_out]  # written always, kept when emitted
                estimate.t, estimate.x, estimate.y, estimate.z, estimate.step = stamp_us, x, y, z, k + 2
                if keep_raw:
                    out_raw[n_out] = raw
                n_out += slot == EMITTED - REJECTED
        # 3. Facilitations, applied when step k is complete.
        if n_pend == pend.shape[0]:  # more than one spike per pixel in a step
            cursor[N_PEND], cursor[CURRENT], cursor[BASE] = n_pend, current, base
            return n_out, n_tot, PENDING_FULL
        pend[n_pend] = (np.int64(u) << 1) | polarity
        n_pend += 1
    cursor[N_PEND], cursor[CURRENT], cursor[BASE] = n_pend, current, base
    if filtering and ts.shape[0] > 0:
        cursor[T_HI] = max(cursor[T_HI], ts[ts.shape[0] - 1])  # later calls must not go back before it
    return n_out, n_tot, OK


@njit(cache=True)
def flush_pending(ints, floats):
    """Apply the buffered facilitations now (their step is complete: no spike of it will come)."""
    ip, cursor, _, _, _, _, _, pend, rec, _, _, _ = views(ints, floats)
    n_pend = cursor[N_PEND]
    if n_pend > 0:
        d, stride, row = ip[DISTANCE], ip[STRIDE], ip[ROW]
        su, sv = np.uint64(2 * stride * d), np.uint64(2 * stride * row * d)
        _flush(rec.view(np.int32), pend, n_pend, (cursor[CURRENT] + 1 - cursor[BASE]) << 1, su, sv)
        cursor[N_PEND] = 0
