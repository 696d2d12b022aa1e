"""The canonical order of outputs: by step, then y, then x (docs/semantics.md, "Output order").

``sort_by_pixel`` puts each step's estimates of the fused kernel (written in trigger order)
in pixel order in place, in time linear in the estimates plus the sensor's rows, from
inside the kernel so that a packet pays no extra dispatch; ``pixel_order`` is the same
order as a permutation, for records of any payload (``backends.graph.canonical``). How the
sort works on raw 32-bit words: docs/performance.md, "How the kernel is built".
"""

from __future__ import annotations

import sys

import numpy as np
from numba import njit

from tofnet.events import DEPTH_DTYPE

#: 32-bit words per depth record, and the word holding ``(y << 16) | x``; the step is words 5-6.
WORDS, KEY = 7, 2
assert DEPTH_DTYPE.itemsize == 4 * WORDS and DEPTH_DTYPE.fields["x"][1] == 4 * KEY
assert DEPTH_DTYPE.fields["y"][1] == 4 * KEY + 2 and DEPTH_DTYPE.fields["step"][1] == 20
assert sys.byteorder == "little", "the canonical sort reads records as little-endian words"


@njit(cache=True)
def _sort_words(words, lo, hi, height, scratch, row_start):
    i = lo
    while i < hi:
        step_lo, step_hi = words[i, 5], words[i, 6]
        j = i + 1
        ordered = True
        while j < hi and words[j, 5] == step_lo and words[j, 6] == step_hi:
            ordered &= words[j, KEY] >= words[j - 1, KEY]
            j += 1
        if not ordered:
            row_start[:height + 1] = 0
            for q in range(i, j):
                row_start[(words[q, KEY] >> 16) + 1] += 1
            for r in range(height):
                row_start[r + 1] += row_start[r]
            for q in range(i, j):
                y = words[q, KEY] >> 16
                at = row_start[y]
                for w in range(WORDS):
                    scratch[at, w] = words[q, w]
                row_start[y] = at + 1
            n = j - i
            for q in range(1, n):  # within a row, by x (stable): rows hold a few estimates
                p = q
                while p > 0 and scratch[p, KEY] < scratch[p - 1, KEY]:
                    for w in range(WORDS):
                        scratch[p, w], scratch[p - 1, w] = scratch[p - 1, w], scratch[p, w]
                    p -= 1
            for q in range(n):
                for w in range(WORDS):
                    words[i + q, w] = scratch[q, w]
        i = j


@njit(cache=True)
def sort_by_pixel(out, lo, hi, height, scratch, row_start):
    """Sort depth records ``out[lo:hi]`` (sorted by step) by (step, y, x) in place, stably.

    ``scratch``: ``(at least hi - lo, WORDS)`` uint32; ``row_start``: at least ``height + 1`` int64.
    """
    _sort_words(out.view(np.uint32).reshape(-1, WORDS), lo, hi, height, scratch, row_start)


@njit(cache=True)
def pixel_order(step, y, x, minor, height):
    """The stable permutation that puts records sorted by ``step`` into (step, y, x, minor)
    order: per step, a counting sort by row (``y < height``), then by (x, minor) within rows."""
    n = step.shape[0]
    order = np.arange(n)
    row_start = np.zeros(height + 1, np.int64)
    scratch = np.empty(n, np.int64)
    i = 0
    while i < n:
        j = i + 1
        ordered = True
        while j < n and step[j] == step[i]:
            if ordered and (y[j] < y[j - 1] or (y[j] == y[j - 1] and (
                    x[j] < x[j - 1] or (x[j] == x[j - 1] and minor[j] < minor[j - 1])))):
                ordered = False
            j += 1
        if not ordered:
            row_start[:] = 0
            for q in range(i, j):
                row_start[y[q] + 1] += 1
            for r in range(height):
                row_start[r + 1] += row_start[r]
            for q in range(i, j):
                at = row_start[y[q]]
                scratch[at] = q
                row_start[y[q]] = at + 1
            for q in range(1, j - i):  # within a row, by (x, minor), stable: rows hold a few records
                p, moving = q, scratch[q]
                while p > 0 and y[scratch[p - 1]] == y[moving] and (
                        x[scratch[p - 1]] > x[moving] or (x[scratch[p - 1]] == x[moving]
                                                          and minor[scratch[p - 1]] > minor[moving])):
                    scratch[p] = scratch[p - 1]
                    p -= 1
                scratch[p] = moving
            order[i:j] = scratch[:j - i]
        i = j
    return order
