"""The depth layer on its own: time-of-travel counter spikes and velocity updates in, depth out.

The unfused twin of the depth part of ``time_of_travel.process``: both call the same
``refresh_sample`` (``A t``/``W`` per sample and update) and ``depth_of`` (eq. 8). It runs on the state of a ``region.TimeOfTravelKernel`` (sample tables,
``A t``/``W`` caches, counts) built for the depth layer's region.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tofnet.kernels.time_of_travel import (DT, EMITTED, REJECTED, T0, X0, X1, Y0, Y1, depth_of, depth_params,
                                          refresh_sample, views)

# Slots of the velocity state carried between calls: the velocity the neurons hold (m/s) and its update id.
VEL_TX, VEL_TY, VEL_TZ, VEL_ID = range(4)


@njit(cache=True)
def depth_from_counts(c_step, c_x, c_y, c_dir, c_count, v_step, v_t, velocity, ints, floats, out, out_raw, n_out):
    """Depth estimates of counter spikes; returns ``(n_out, status)`` (0 ok, 1 unsorted).

    Counter spikes ``(sent step m, x, y, direction, count)`` are sorted by step with the spikes
    of one pixel and step together (canonical order); they reach the depth neuron in step
    ``m + 1``, which holds the latest velocity update sent at or before ``m``. Velocity updates
    ``(sent step, t)`` are sorted by step; ``velocity`` carries the held update across calls.
    Estimates go to ``out[n_out:]`` stamped with step ``m + 1`` and ``t0 + (m + 2) * dt`` µs.
    """
    ip, cursor, counts, rows, cols, cache_j, cache_w, pend, rec, fp, points, cache_at = views(ints, floats)
    n, n_vel = c_step.shape[0], v_step.shape[0]
    for i in range(1, n):
        if c_step[i] < c_step[i - 1]:
            return n_out, 1
    params = depth_params(ip, fp)
    keep_raw = out_raw.shape[0] > 0
    x0, y0, x1, y1, t0, dt = ip[X0], ip[Y0], ip[X1], ip[Y1], ip[T0], ip[DT]
    tx, ty, tz, update = velocity[VEL_TX], velocity[VEL_TY], velocity[VEL_TZ], np.int64(velocity[VEL_ID])
    v = 0
    i = 0
    while i < n:
        m, x, y = c_step[i], np.int64(c_x[i]), np.int64(c_y[i])
        m0 = m1 = m2 = m3 = np.int64(0)
        while i < n and c_step[i] == m and c_x[i] == x and c_y[i] == y:
            d, value = c_dir[i], np.int64(c_count[i])
            if d == 0:
                m0 = value
            elif d == 1:
                m1 = value
            elif d == 2:
                m2 = value
            else:
                m3 = value
            i += 1
        while v < n_vel and v_step[v] <= m:  # updates sent up to step m have arrived by step m + 1
            tx, ty, tz = v_t[v, 0], v_t[v, 1], v_t[v, 2]
            update += 1
            v += 1
        if x0 <= x < x1 and y0 <= y < y1:
            sample = rows[y - y0] + cols[x - x0]
            if cache_j[sample] != update:
                refresh_sample(sample, update, tx, ty, tz, params, cache_j, cache_w, cache_at, points)
            z, raw, slot = depth_of(m0, m1, m2, m3, 1, cache_w[2 * sample], cache_w[2 * sample + 1],
                                    cache_at[2 * sample], cache_at[2 * sample + 1], params)
            counts[REJECTED + slot] += 1
            if slot == EMITTED - REJECTED:
                estimate = out[n_out]
                estimate.t, estimate.x, estimate.y, estimate.z, estimate.step = t0 + (m + 2) * dt, x, y, z, m + 1
                if keep_raw:
                    out_raw[n_out] = raw
                n_out += 1
    while v < n_vel:  # later updates: held for the next call's spikes
        tx, ty, tz = v_t[v, 0], v_t[v, 1], v_t[v, 2]
        update += 1
        v += 1
    velocity[VEL_TX], velocity[VEL_TY], velocity[VEL_TZ], velocity[VEL_ID] = tx, ty, tz, update
    return n_out, 0
