"""The pixel model: events at log-intensity threshold crossings between two renders (ESIM's method).

Each pixel keeps a reference log intensity. Between renders at ``t0`` and ``t1`` its
log intensity is taken to change linearly from ``L0`` to ``L1``; every time it
crosses ``ref + C+`` (or ``ref - C-``) an ON (OFF) event is emitted at the linearly
interpolated time and the reference moves by exactly one threshold, so a large change
gives several events spread over the interval.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Smallest contrast threshold a pixel may get after noise (ESIM clamps the same way).
MIN_THRESHOLD = 0.01
#: Relative depth jump between two renders above which a pixel is taken to have
#: changed surface; its events then get the depth of the nearer render in time
#: instead of a meaningless blend of foreground and background.
DEPTH_JUMP = 0.05


def thresholds(n: int, mean: float, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Per-pixel contrast thresholds ``N(mean, sigma)`` clamped to ``MIN_THRESHOLD`` (fixed-pattern noise)."""
    if sigma <= 0:
        return np.full(n, max(mean, MIN_THRESHOLD))
    return np.maximum(rng.normal(mean, sigma, size=n), MIN_THRESHOLD)


@njit(cache=True)
def count_crossings(l0, l1, ref, c_on, c_off):  # pragma: no cover - numba
    """How many events ``emit_crossings`` will write for this interval (the reference is not changed)."""
    total = 0
    for i in range(l0.shape[0]):
        if l1[i] > l0[i]:
            d = l1[i] - ref[i]
            if d >= c_on[i]:
                total += int(d / c_on[i])
        elif l1[i] < l0[i]:
            d = ref[i] - l1[i]
            if d >= c_off[i]:
                total += int(d / c_off[i])
    return total


@njit(cache=True)
def emit_crossings(l0, l1, d0, d1, ref, c_on, c_off, t0, t1, width, depth_jump, nearer_at_jumps,
                   out_t, out_x, out_y, out_p, out_d, n):  # pragma: no cover - numba
    """Write the events of the interval ``[t0, t1]`` (µs) from index ``n``; return the new count.

    ``out_t`` gets integer microseconds (rounded), ``out_d`` the depth at the event
    time: linear between ``d0`` and ``d1``, or the nearer render's if the depth jumped
    by more than ``depth_jump`` (relative) — or, with ``nearer_at_jumps``, the nearer of
    the two. ``ref`` is updated in place.
    """
    span = t1 - t0
    for i in range(l0.shape[0]):
        a = l0[i]
        b = l1[i]
        # Same counts as count_crossings: m whole thresholds between ref and the end value.
        if b > a:
            c = c_on[i]
            pol = 1
            d = b - ref[i]
        elif b < a:
            c = -c_off[i]
            pol = 0
            d = ref[i] - b
        else:
            continue
        if d < abs(c):
            continue
        m = int(d / abs(c))
        za = d0[i]
        zb = d1[i]
        jump = abs(zb - za) > depth_jump * min(za, zb)
        r = ref[i]
        for j in range(1, m + 1):
            level = r + j * c
            frac = min(max((level - a) / (b - a), 0.0), 1.0)
            out_t[n] = np.int64(np.floor(t0 + frac * span + 0.5))
            out_x[n] = i % width
            out_y[n] = i // width
            out_p[n] = pol
            if jump and nearer_at_jumps:
                out_d[n] = min(za, zb)
            elif jump:
                out_d[n] = za if frac < 0.5 else zb
            else:
                out_d[n] = za + frac * (zb - za)
            n += 1
        ref[i] = r + m * c
    return n
