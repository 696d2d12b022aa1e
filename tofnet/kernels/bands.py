"""Moving events to bands and their outputs back (numba; the bands themselves: ``tofnet.backends.bands``).

``select_rows`` copies a packet's events of a band's rows (widened by the input reach) in
their order, so each band's kernel reads only its events (each band selects its own, in its
thread);
``merge_by_step`` joins the bands' outputs, each sorted by step, into one array sorted by
step and, within a step, in band order: the canonical order when each band's part is in
it, as bands are strips of rows from the top.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def row_load(events, height, every):
    """Events per row (``height``) among every ``every``-th event; events outside the sensor are not counted."""
    load = np.zeros(height, np.int64)
    for i in range(0, events.shape[0], every):
        y = np.int64(events[i].y)
        if y < height:
            load[y] += 1
    return load


@njit(cache=True, nogil=True)
def select_rows(events, lo, hi, width, height, outside, out):
    """Copy the events of rows ``[lo, hi)`` (and, with ``outside``, those outside the sensor) to ``out``
    (room for ``len(events) + 1``), in order; returns how many. Without branches: a band's events
    are a coin toss among the packet's, which a branch predictor cannot learn."""
    m = 0
    keep_outside = np.int64(outside)
    for i in range(events.shape[0]):
        e = events[i]
        x, y = np.int64(e.x), np.int64(e.y)
        out[m] = e
        inside = np.int64(y >= lo) & np.int64(y < hi) & np.int64(x < width)
        m += inside | ((np.int64(x >= width) | np.int64(y >= height)) & keep_outside)
    return m


@njit(cache=True, nogil=True)
def merge_by_step(src, steps, parts, dst, at, width):
    """Copy the records ``src[lo:hi]`` of each part (rows of ``parts``: ``lo, hi``; each part sorted by
    ``steps``) to ``dst[at:]`` sorted by step, parts in order within a step; returns the end in ``dst``.
    ``src``/``dst``: the records as flat words, ``width`` per record (``tofnet.backends.bands.words``)."""
    n_parts = parts.shape[0]
    cursor = parts[:, 0].copy()
    while True:
        best, best_step = -1, np.int64(0)
        for b in range(n_parts):
            if cursor[b] < parts[b, 1] and (best < 0 or steps[cursor[b]] < best_step):
                best, best_step = b, steps[cursor[b]]
        if best < 0:
            return at
        lo = q = cursor[best]
        hi = parts[best, 1]
        while q < hi and steps[q] == best_step:  # the whole step of this part at once
            q += 1
        for w in range((q - lo) * width):
            dst[at * width + w] = src[lo * width + w]
        at += q - lo
        cursor[best] = q
