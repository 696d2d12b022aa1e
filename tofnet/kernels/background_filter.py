"""The background-activity filter over spikes, event-driven (``BackgroundActivityFilterProcess``)."""

from __future__ import annotations

import numpy as np
from numba import njit

NEVER_STEP = -(1 << 62)  # "no spike yet": older than any window


@njit(cache=True)
def filter_spikes(step, x, y, p, last, x0, y0, x1, y1, pad, row, radius, window, out, counts):
    """Spikes (received step, x, y, polarity; sorted by step) that a neighbour supports.

    ``last[(y - y0 + pad) * row + x - x0 + pad]`` is the latest step a pixel of the region
    ``[x0, x1) x [y0, y1)`` or its ``pad``-wide halo received a spike. A step's spikes are
    first all recorded, then each one inside the region is checked against its neighbours
    (Chebyshev distance 1..radius) for a spike in steps ``k - window .. k``. Passing spikes
    go to ``out``, stamped ``k`` (sent on in the step they arrived); ``counts`` = [passed, isolated].
    Returns how many passed.
    """
    n = step.shape[0]
    n_out = 0
    i = 0
    while i < n:
        k = step[i]
        j = i
        while j < n and step[j] == k:
            xi, yi = np.int64(x[j]), np.int64(y[j])
            if x0 - pad <= xi < x1 + pad and y0 - pad <= yi < y1 + pad:
                last[(yi - y0 + pad) * row + xi - x0 + pad] = k
            j += 1
        for q in range(i, j):
            xi, yi = np.int64(x[q]), np.int64(y[q])
            if not (x0 <= xi < x1 and y0 <= yi < y1):
                continue
            supported = False
            for dv in range(-radius, radius + 1):
                base = (yi - y0 + pad + dv) * row + xi - x0 + pad
                for du in range(-radius, radius + 1):
                    if (du != 0 or dv != 0) and last[base + du] >= k - window:
                        supported = True
            if supported:
                out[n_out].step, out[n_out].x, out[n_out].y, out[n_out].p = k, xi, yi, p[q]
                n_out += 1
                counts[0] += 1
            else:
                counts[1] += 1
        i = j
    return n_out
