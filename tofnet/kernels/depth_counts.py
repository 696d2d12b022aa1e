"""The depth layer on its own: time-of-travel counter spikes and velocity updates in, depth out.

The unfused twin of the depth part of ``time_of_travel.process``: both call the same
``refresh_sample`` (``A t``/``W`` per sample and update) and ``depth_of`` (eq. 8). It runs
on the state of a ``region.TimeOfTravelKernel`` (sample tables, ``A t``/``W`` caches,
counts) built for the depth layer's region. With angular velocity updates it computes
eq. 7 instead (``depth_rotation_of``), which only this path does: the fused kernel runs
the paper's network, eq. 8.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tofnet.kernels.depth import EMITTED as KEPT
from tofnet.kernels.depth import classify_rotation, float_depth_rotation, translational_share
from tofnet.kernels.fixed_point import fixed_depth_rotation, fixed_share, quantize
from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.time_of_travel import (DT, EMITTED, N_REASONS, REJECTED, T0, X0, X1, Y0, Y1, axis_count,
                                          depth_of, depth_params, refresh_sample, views)

# Slots of the velocity state carried between calls: the velocity the neurons hold (m/s) and its update id.
VEL_TX, VEL_TY, VEL_TZ, VEL_ID = range(4)
# Slots of the rotation state carried between calls: the angular velocity the neurons hold (rad/s).
ROT_WX, ROT_WY, ROT_WZ = range(3)


@njit(cache=True)
def depth_rotation_of(m0, m1, m2, m3, w_x, w_y, at_x, at_y, bw_x, bw_y, params, min_share, min_share_raw):
    """The depth neuron with rotation (paper eq. 7; docs/semantics.md, docs/fixed_point.md): ``(z metres,
    raw fixed-point z or 0, outcome slot)`` from its counters, its sample's ``W``/``A t`` and its pixel's
    ``B ω`` (px/s). Fixed point: ``V = quantize(B ω * dt / distance)`` like ``W``, the share
    ``r_raw = 2**F − s·V``, rejected at or below ``min_share_raw``, else ``Z_raw = round(N 2**F / r_raw)``."""
    fixed, frac_bits, payload_bits, lsb, min_raw, max_raw, min_depth, max_depth, _, _, _, _, spc = params
    sx, sy = axis_count(m0, m1), axis_count(m2, m3)
    measured = (sx | sy) != 0
    if fixed:
        v_x = quantize(bw_x * spc, frac_bits, payload_bits)
        v_y = quantize(bw_y * spc, frac_bits, payload_bits)
        share_raw = fixed_share(sx, sy, v_x, v_y, frac_bits)
        raw = np.int64(0)
        if share_raw > min_share_raw:
            raw = fixed_depth_rotation(sx, sy, w_x, w_y, share_raw, frac_bits, payload_bits)
        code = classify_rotation(measured, share_raw, raw, min_share_raw, min_raw, max_raw)
        z = raw * lsb
    else:
        raw = np.int64(0)
        share = translational_share(sx, sy, bw_x, bw_y, spc)
        z = float_depth_rotation(sx, sy, at_x, at_y, bw_x, bw_y, spc)
        code = classify_rotation(measured, share, z, min_share, min_depth, max_depth)
    return z, raw, (N_REASONS if code == KEPT else code)


@njit(cache=True)
def depth_from_counts(spikes, v_step, v_t, velocity, w_step, w_omega, omega, rotation, ints, floats, out, out_raw,
                      n_out):
    """Depth estimates of counter spikes; returns ``(n_out, status)`` (0 ok, 1 unsorted).

    Counter spikes ``spikes`` (``TOT_DTYPE``: sent step m, x, y, direction, count) are sorted by step with the spikes
    of one pixel and step together (canonical order); they reach the depth neuron in step
    ``m + 1``, which holds the latest velocity update sent at or before ``m``. Velocity updates
    ``(sent step, t)`` are sorted by step; ``velocity`` carries the held update across calls.
    ``rotation`` is ``(min_share, min_share_raw, fx, fy, cx, cy)`` for eq. 7 (the intrinsics of
    ``B ω``) and empty for eq. 8; angular
    velocity updates ``(w_step, w_omega)`` are held like the velocity's (``omega`` across calls).
    Estimates go to ``out[n_out:]`` stamped with step ``m + 1`` and ``t0 + (m + 2) * dt`` µs.
    """
    # the records' fields, read in place (strided); taken here, so that the signature is the records' type
    # whatever their number (numba types the fields of 0 or 1 records as contiguous, of more as strided)
    c_step, c_x, c_y, c_dir, c_count = spikes.step, spikes.x, spikes.y, spikes.direction, spikes.count
    ip, cursor, counts, rows, cols, cache_j, cache_w, pend, rec, fp, points, cache_at = views(ints, floats)
    n, n_vel = c_step.shape[0], v_step.shape[0]
    for i in range(1, n):
        if c_step[i] < c_step[i - 1]:
            return n_out, 1
    params = depth_params(ip, fp)
    keep_raw = out_raw.shape[0] > 0
    x0, y0, x1, y1, t0, dt = ip[X0], ip[Y0], ip[X1], ip[Y1], ip[T0], ip[DT]
    tx, ty, tz, update = velocity[VEL_TX], velocity[VEL_TY], velocity[VEL_TZ], np.int64(velocity[VEL_ID])
    rotating = rotation.shape[0] > 0
    min_share = rotation[0] if rotating else 0.0
    min_share_raw = np.int64(rotation[1]) if rotating else np.int64(0)
    fx, fy, cx, cy = (rotation[2], rotation[3], rotation[4], rotation[5]) if rotating else (1.0, 1.0, 0.0, 0.0)
    wx, wy, wz = omega[ROT_WX], omega[ROT_WY], omega[ROT_WZ]
    n_w = w_step.shape[0]
    v = 0
    w = 0
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
        while w < n_w and w_step[w] <= m:  # likewise for the angular velocity
            wx, wy, wz = w_omega[w, 0], w_omega[w, 1], w_omega[w, 2]
            w += 1
        if x0 <= x < x1 and y0 <= y < y1:
            sample = rows[y - y0] + cols[x - x0]
            if cache_j[sample] != update:
                refresh_sample(sample, update, tx, ty, tz, params, cache_j, cache_w, cache_at, points)
            if rotating:  # B ω at the pixel itself, whatever the sampling of A t
                bw_x, bw_y = rotational_flow(wx, wy, wz, float(x), float(y), fx, fy, cx, cy)
                z, raw, slot = depth_rotation_of(m0, m1, m2, m3, cache_w[2 * sample], cache_w[2 * sample + 1],
                                                 cache_at[2 * sample], cache_at[2 * sample + 1], bw_x, bw_y,
                                                 params, min_share, min_share_raw)
            else:
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
    if n_w:
        wx, wy, wz = w_omega[n_w - 1, 0], w_omega[n_w - 1, 1], w_omega[n_w - 1, 2]
    omega[ROT_WX], omega[ROT_WY], omega[ROT_WZ] = wx, wy, wz
    return n_out, 0
