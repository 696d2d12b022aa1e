"""The canonical order of outputs: by step, then y, then x (docs/semantics.md, "Output order").

The fused kernel writes estimates in the order of the events that triggered them; this puts
each step's estimates in pixel order in place, in time linear in the estimates plus the
sensor's rows (a counting sort by row, then an insertion sort by column within rows, which
hold one or two estimates each).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def sort_steps_by_pixel(out, lo, hi, height, scratch, row_start):
    """Sort ``out[lo:hi]`` (records with ``step``, ``y``, ``x``, sorted by step) by (step, y, x).

    ``scratch`` holds at least ``hi - lo`` records; ``row_start`` at least ``height + 1`` ints.
    Records of one step and pixel keep their order (stable).
    """
    i = lo
    while i < hi:
        step = out[i].step
        j = i + 1
        ordered = True
        while j < hi and out[j].step == step:
            if out[j].y < out[j - 1].y or (out[j].y == out[j - 1].y and out[j].x < out[j - 1].x):
                ordered = False
            j += 1
        if not ordered:
            row_start[:height + 1] = 0
            for q in range(i, j):
                row_start[out[q].y + 1] += 1
            for r in range(height):
                row_start[r + 1] += row_start[r]
            for q in range(i, j):
                y = out[q].y
                scratch[row_start[y]] = out[q]
                row_start[y] += 1
            n = j - i
            for q in range(1, n):  # within a row, by x (stable); records are views: move a copy
                if scratch[q].y == scratch[q - 1].y and scratch[q].x < scratch[q - 1].x:
                    moving = scratch[q:q + 1].copy()
                    p = q - 1
                    while p >= 0 and scratch[p].y == moving[0].y and scratch[p].x > moving[0].x:
                        scratch[p + 1] = scratch[p]
                        p -= 1
                    scratch[p + 1] = moving[0]
            for q in range(n):
                out[i + q] = scratch[q]
        i = j
