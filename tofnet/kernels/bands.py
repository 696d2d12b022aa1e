"""Moving events to bands and their outputs back (numba; the bands themselves: ``tofnet.backends.bands``).

``select_rows`` lists the positions of a packet's events of a band's rows (widened by the
input reach), so each band's kernel reads only its events (each band selects its own, in its
thread), and checks the packet's time order on the way (``clocked_columns``: the columns of its
events and each step's first event, for kernels that keep a clock); ``touch`` writes the first byte of fresh
pages, so that threads share the first touch of an output buffer; ``merge_by_step`` joins the bands' outputs, each sorted by step, into one array
sorted by step and, within a step, in band order: the canonical order when each band's part
is in it, as bands are strips of rows from the top; ``merge_cuts`` splits that merge into
shares that threads run side by side.
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
def select_rows(events, keep, index):
    """Write to ``index`` (room for ``len(events) + 1``) the positions of the events whose row ``y`` has
    ``keep[y]`` (uint8, 65536 entries: rows past the sensor too), in order; returns how many, or -1
    when the packet is not in time order (checked over all its events, so every band gives the same
    answer, and the kernel run on ``index`` skips its own pass over the packet: one read of the
    packet per band instead of two). Without branches (a band's events are a coin toss among the
    packet's, which a branch predictor cannot learn), and positions, not records: the kernel reads
    the band's events in the packet itself."""
    m = 0
    n = events.shape[0]
    back = False
    previous = events[0].t if n else 0
    for i in range(n):
        t = events[i].t
        back |= t < previous
        previous = t
        index[m] = i
        m += keep[events[i].y]
    return -1 if back else m


@njit(cache=True, nogil=True)
def clocked_columns(events, keep, t0, dt, width, height):
    """``(m, t, x, y, p)``: the columns (``EVENT_DTYPE``'s types, room for every event) whose first ``m``
    entries are the events whose row has ``keep[y]`` (as ``select_rows``) and the first event of
    every step (``dt`` µs from ``t0``) that a per-event clock reads: within the sensor (``x < width``,
    ``y < height``), not before ``t0``; ``m`` -1 when the packet is not in time order. A band whose
    kernel keeps a clock of the steps (the time surface's travel ring and motion epochs) then moves
    it at the events the whole sensor's kernel does. One pass writing every event's fields at the
    cursor, which moves on the kept ones (no branch on the row: a coin toss); the clock's branch is
    taken once per step. 3.0 ns per event against 2.5 + 1.5 for positions then a gather (slider)."""
    n = events.shape[0]
    t, x, y, p = np.empty(n, np.int64), np.empty(n, np.uint16), np.empty(n, np.uint16), np.empty(n, np.uint8)
    m = 0
    back = False
    previous = events[0].t if n else 0
    step_end = np.int64(t0)  # the first event at or after t0 starts a step
    for i in range(n):
        e = events[i]
        ti, yi = e.t, e.y
        back |= ti < previous
        previous = ti
        add = keep[yi]
        if ti >= step_end:
            if np.int64(e.x) < width and np.int64(yi) < height:
                add = 1
                step_end = t0 + ((ti - t0) // dt + 1) * dt
        t[m], x[m], y[m], p[m] = ti, e.x, yi, e.p
        m += add
    return (-1 if back else m), t, x, y, p


@njit(cache=True, nogil=True)
def touch(raw, address, lo, hi, part, parts, block):
    """Write 0 to the first byte of every 4 KB page that starts in ``raw[lo:hi]`` (bytes; ``address``:
    where ``raw`` starts in memory) and lies in a ``block``-byte block numbered ``part`` modulo
    ``parts``: the first touch of fresh pages (by far their dearest use on a virtual machine), shared
    between ``parts`` threads."""
    page = 4096
    i = lo + (-(address + lo)) % page
    while i < hi:
        if ((address + i) // block) % parts == part:
            raw[i] = 0
        i += page


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
        dst[at * width:(at + q - lo) * width] = src[lo * width:q * width]  # a block copy, not word by word
        at += q - lo
        cursor[best] = q


@njit(cache=True, nogil=True)
def merge_cuts(steps, parts, shares):
    """Where ``shares`` threads cut the parts (rows ``lo, hi`` of ``parts``, each sorted by ``steps``) to
    merge them side by side: row ``k`` of the result holds, per part, the first record of share ``k``'s
    steps (row 0: the parts' starts, row ``shares``: their ends). Shares split the largest part
    evenly, at step boundaries, and every part at the same steps."""
    n_parts = parts.shape[0]
    cuts = np.empty((shares + 1, n_parts), np.int64)
    cuts[0] = parts[:, 0]
    cuts[shares] = parts[:, 1]
    big = 0
    for b in range(n_parts):
        if parts[b, 1] - parts[b, 0] > parts[big, 1] - parts[big, 0]:
            big = b
    size = parts[big, 1] - parts[big, 0]
    for k in range(1, shares):
        if size == 0:
            cuts[k] = parts[:, 1]
            continue
        step = steps[parts[big, 0] + (k * size) // shares]
        for b in range(n_parts):
            lo, hi = parts[b, 0], parts[b, 1]
            while lo < hi:  # the first record of a step >= ``step``
                mid = (lo + hi) // 2
                if steps[mid] < step:
                    lo = mid + 1
                else:
                    hi = mid
            cuts[k, b] = max(lo, cuts[k - 1, b])
    return cuts
