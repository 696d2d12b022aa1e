"""Event-driven time-of-travel layer and depth neuron (numba core; the API is ``tofnet.kernels.region``).

Implements docs/semantics.md with the timestamp formulation: a unit stores the step
``a`` of its last facilitation and that spike's polarity instead of a counter, so
``counter = now - a`` at the start of step ``now`` and the work is proportional to
events, not to pixels x steps. An accepted input spike of input step ``k``

- triggers the four units of its pixel in step ``now = k+1`` (pixel inside the region),
- facilitates unit ``(pixel + distance*D, D)`` in step ``k+1`` for each direction ``D``
  (pixel inside the region or its halo),
- and the counters that fired reach the pixel's depth neuron in step ``k+2``.

All triggers of a step are resolved before any facilitation of that step. A step is
processed as a run of spikes: triggers, then facilitations. The last step of a call may
continue in the next call, so its facilitations wait in a buffer that is part of the
state; packets may therefore be split anywhere, even inside a step.

State layout (chosen for speed: random pixels make this cache-bound). One int32
``stamp`` per unit, ``((a - base) << 1) | polarity``, in an array ``[H + 4d, W + 4d, 4]``
(region padded by ``2*distance`` so facilitation writes need no bounds checks; padding
units never trigger). ``base`` moves forward ("rebase") before the stamps could
overflow int32, about every 2**30 steps (12 days at 1 ms). For a trigger of polarity
``p`` the difference ``key - stamp`` with ``key = ((now - base) << 1) | p`` is
``2*(now - a)`` when the polarities match and odd otherwise, so one subtraction tests
both. Idle units hold ``IDLE``, whose difference exceeds any counter maximum.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tofnet.kernels.depth import EMITTED, classify, float_depth, signed_axis_count
from tofnet.kernels.fixed_point import fixed_depth, quantize
from tofnet.kernels.velocity import velocity_term

#: Stamp of an idle unit (never facilitated, sent since, or overflowed at a rebase).
IDLE = -(1 << 31)
#: Rebase when ``now - base`` exceeds this, keeping ``key`` below 2**31.
REBASE_AFTER = (1 << 30) - 4
# Kernel status codes.
OK, UNSORTED, PENDING_FULL, NO_VELOCITY = 0, 1, 2, 3
# Cursor slots: buffered facilitations, current input step, stamp base.
N_PEND, CURRENT, BASE = 0, 1, 2


@njit(cache=True)
def _facilitate(stamp, xs, ys, ps, lo, hi, key_base, hx0, hy0, hx1, hy1, pad_x, pad_y, row, d):
    """Facilitate, from spikes ``lo .. hi-1``, units ``(x + d*D, D)`` with stamp ``key_base | polarity``."""
    du, dv = np.uint64(4 * d), np.uint64(row * d)
    for e in range(lo, hi):
        x, y = xs[e], ys[e]
        if hx0 <= x < hx1 and hy0 <= y < hy1:
            key = np.int32(key_base | (1 if ps[e] != 0 else 0))
            unit = np.uint64((y + pad_y) * row + (x + pad_x) * 4)  # unsigned: no wraparound checks
            stamp[unit + du] = key  # +u: the pixel an edge moving +u reaches next
            stamp[unit - du + np.uint64(1)] = key  # -u
            stamp[unit + dv + np.uint64(2)] = key  # +v
            stamp[unit - dv + np.uint64(3)] = key  # -v


@njit(cache=True)
def _buffer(xs, ys, ps, lo, hi, pend_x, pend_y, pend_p, n_pend, hx0, hy0, hx1, hy1):
    """Append the spikes of an unfinished step that facilitate the region; -1 when full."""
    for e in range(lo, hi):
        x, y = xs[e], ys[e]
        if hx0 <= x < hx1 and hy0 <= y < hy1:
            if n_pend == pend_x.shape[0]:  # more than one spike per pixel in a step
                return -1
            pend_x[n_pend], pend_y[n_pend], pend_p[n_pend] = x, y, ps[e]
            n_pend += 1
    return n_pend


@njit(cache=True)
def _rebase(stamp, base, new_base, counter_max):
    """Re-express stamps relative to ``new_base``; units too old to ever fire become idle."""
    shift = (new_base - base) << 1
    for i in range(stamp.shape[0]):
        s = stamp[i]
        if s != IDLE:
            v = np.int64(s) - shift
            if -(v >> 1) > counter_max:  # age at new_base: past the counter maximum
                stamp[i] = IDLE
            else:
                stamp[i] = v


@njit(cache=True)
def process_spikes(steps, xs, ys, ps, stamp, cursor, pend_x, pend_y, pend_p,
                   x0, y0, x1, y1, distance, counter_max, rebase_after,
                   samples, points, cache_j, cache_at, cache_w, velocity, first_update, update_every,
                   fx, fy, cx, cy,
                   fixed, seconds_per_count, min_depth, max_depth, frac_bits, payload_bits, min_raw, max_raw,
                   t0_us, timestep_us, out, out_raw, rejected, record_tot, tot):
    """Run sorted accepted spikes through a region; returns (n_depth, n_tot, n_spikes, status).

    ``samples[pixel]`` indexes ``points`` (where ``A t`` is evaluated); pixels of one patch
    share an index, so ``A t`` and ``W`` are computed once per velocity update ``j`` and
    cached (``cache_j`` the update each cache entry holds, ``cache_at`` / ``cache_w``).

    Depth estimates go to ``out`` (``DEPTH_DTYPE``) and their fixed-point values to
    ``out_raw``; the time-of-travel spikes to ``tot`` (``TOT_DTYPE``) when ``record_tot``;
    ``rejected`` counts by reason.
    """
    n = steps.shape[0]
    previous = max(cursor[CURRENT], 0)
    for i in range(n):  # check first, so that bad input leaves the state untouched
        if steps[i] < previous:
            return 0, 0, 0, UNSORTED
        previous = steps[i]
    if n and ((steps[0] + 1) // update_every < first_update or
              (steps[n - 1] + 1) // update_every - first_update >= velocity.shape[0]):
        return 0, 0, 0, NO_VELOCITY
    n_pend, current, base = cursor[N_PEND], cursor[CURRENT], cursor[BASE]
    d = distance
    pad_x, pad_y = 2 * d - x0, 2 * d - y0
    row_len = 4 * (x1 - x0 + 4 * d)  # stamps per padded row
    hx0, hy0, hx1, hy1 = x0 - d, y0 - d, x1 + d, y1 + d
    max_diff = 2 * counter_max
    lsb = 1.0 / (1 << frac_bits)
    n_out = n_tot = n_spikes = 0
    m = np.zeros(4, dtype=np.int64)  # what the four units of a pixel send
    i = 0
    while i < n:
        k = steps[i]
        j = i + 1
        while j < n and steps[j] == k:
            j += 1
        if k != current:
            if n_pend > 0:  # the buffered part of step `current` is complete
                _facilitate(stamp, pend_x, pend_y, pend_p, 0, n_pend, (current + 1 - base) << 1,
                            hx0, hy0, hx1, hy1, pad_x, pad_y, row_len, d)
                n_pend = 0
            current = k
            if k + 1 - base > rebase_after:
                _rebase(stamp, base, k + 1, counter_max)
                base = k + 1
        now = k + 1
        key_now = (now - base) << 1
        # The depth neurons of this step's spikes run in step k+2 and hold velocity update (k+1) // U
        # (hoisted: an int64 division per spike costs more than the rest of the depth neuron).
        update = (k + 1) // update_every
        row = update - first_update
        tx, ty, tz = velocity[row, 0], velocity[row, 1], velocity[row, 2]
        stamp_us = t0_us + (k + 3) * timestep_us  # end of depth step k+2
        # 1. Triggers (inline: a helper taking arrays costs refcount atomics per call).
        for e in range(i, j):
            x, y = xs[e], ys[e]
            if not (x0 <= x < x1 and y0 <= y < y1):
                continue
            key = key_now | (1 if ps[e] != 0 else 0)
            unit = np.uint64((y + pad_y) * row_len + (x + pad_x) * 4)
            fired = 0
            for c in range(4):
                diff = key - stamp[unit + np.uint64(c)]  # 2*(now - a) if same polarity, odd otherwise
                if 2 <= diff <= max_diff and (diff & 1) == 0:
                    stamp[unit + np.uint64(c)] = IDLE  # idle until facilitated again
                    m[c] = diff >> 1
                    fired += 1
                else:  # idle, overflowed, or the other polarity (that counter keeps running)
                    m[c] = 0
            if fired == 0:
                continue
            n_spikes += fired
            if record_tot:
                for c in range(4):
                    if m[c] > 0:
                        record = tot[n_tot]
                        record.step, record.x, record.y, record.direction, record.count = now, x, y, c, m[c]
                        n_tot += 1
            # 2. The pixel's depth neuron, one step later.
            sx = signed_axis_count(m[0], m[1])
            sy = signed_axis_count(m[2], m[3])
            sample = samples[y - y0, x - x0]
            if cache_j[sample] != update:  # first depth neuron of this patch (or pixel) under this update
                at_x, at_y = velocity_term(tx, ty, tz, points[sample, 0], points[sample, 1], fx, fy, cx, cy)
                cache_at[sample, 0], cache_at[sample, 1] = at_x, at_y
                if fixed:  # W = A t * dt / distance, quantised once on the host (docs/fixed_point.md)
                    cache_w[sample, 0] = quantize(at_x * seconds_per_count, frac_bits, payload_bits)
                    cache_w[sample, 1] = quantize(at_y * seconds_per_count, frac_bits, payload_bits)
                cache_j[sample] = update
            if fixed:
                raw = fixed_depth(sx, sy, cache_w[sample, 0], cache_w[sample, 1], payload_bits)
                reason = classify(sx != 0 or sy != 0, raw, min_raw, max_raw)
                z = raw * lsb
            else:
                raw = 0
                z = float_depth(sx, sy, cache_at[sample, 0], cache_at[sample, 1], seconds_per_count)
                reason = classify(sx != 0 or sy != 0, z, min_depth, max_depth)
            if reason == EMITTED:
                record = out[n_out]
                record.t, record.x, record.y, record.z, record.step = stamp_us, x, y, z, k + 2
                out_raw[n_out] = raw
                n_out += 1
            else:
                rejected[reason] += 1
        # 3. Facilitations, after every trigger of the step.
        if j < n:  # step k ends inside this call
            if n_pend > 0:
                _facilitate(stamp, pend_x, pend_y, pend_p, 0, n_pend, key_now,
                            hx0, hy0, hx1, hy1, pad_x, pad_y, row_len, d)
                n_pend = 0
            _facilitate(stamp, xs, ys, ps, i, j, key_now, hx0, hy0, hx1, hy1, pad_x, pad_y, row_len, d)
        else:  # step k may continue in the next call
            n_pend = _buffer(xs, ys, ps, i, j, pend_x, pend_y, pend_p, n_pend, hx0, hy0, hx1, hy1)
            if n_pend < 0:
                return n_out, n_tot, n_spikes, PENDING_FULL
        i = j
    cursor[N_PEND], cursor[CURRENT], cursor[BASE] = n_pend, current, base
    return n_out, n_tot, n_spikes, OK
