"""The input process: refractory filter, one event per pixel per step, counted drops.

The per-event rule (``admit``) is shared: ``InputFilter`` runs it on its own arrays for
the reference and multiproc backends, and the fused kernel of the ``fixed`` and
``float`` backends (``tofnet.kernels.time_of_travel``) runs it on words of its
per-pixel records, in the same pass as the time-of-travel units.

Per pixel the filter keeps the time (µs) of the last accepted event of each channel
(one channel, or one per polarity) and of the last accepted event of any polarity
(the same word when there is one channel). The step of that last event is not stored:
"already accepted in this step" is ``step_start <= latest < step_end``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Indices into the drop counter array (the drop reasons ``InputProcess.counters`` declares, in
# that order); ACCEPTED follows them, so a counter array of 5 slots takes
# ``counts[admit(...)] += 1`` without a branch.
OUT_OF_BOUNDS, BEFORE_T0, REFRACTORY, SAME_STEP, ACCEPTED = range(5)

NEVER = -(1 << 62)  # "no event yet" (µs): far enough back that any refractory period has passed


@njit(cache=True, inline="always")
def admit(last, word: int, latest: int, t: int, step_start: int, step_end: int, refractory_us: int) -> int:
    """Refractory and same-step rules for one event at time ``t`` µs of step ``[step_start, step_end)``.

    ``last[word]`` is the last accepted time of the event's channel, ``last[latest]`` that of
    the pixel (any polarity). Returns REFRACTORY, SAME_STEP or ACCEPTED (then both are ``t``).
    """
    if t - last[word] < refractory_us:
        return REFRACTORY
    if step_start <= last[latest] < step_end:
        return SAME_STEP
    last[word] = t
    last[latest] = t
    return ACCEPTED


@njit(cache=True)
def filter_events(events, width, height, t0_us, timestep_us, refractory_us, per_polarity,
                  last, pad, row, stride, offset, out_step, out_x, out_y, out_p, counts):
    """Accepted events of one packet (records with fields t, x, y, p) as (input step, x, y, polarity)
    spikes; returns how many.

    The filter word of pixel ``(x, y)`` and channel ``c`` is
    ``last[((y + pad) * row + x + pad) * stride + offset + c]``; the pixel's latest word
    is channel 0 with one channel, else word ``offset + 2``. ``counts`` (5 slots)
    counts drops by reason and the accepted events. Any time order is handled.
    """
    # the records' fields, read in place; taken here, so that the signature is the records' type whatever
    # their number (numba types the fields of 0 or 1 records as contiguous, of more as strided)
    t, x, y, p = events.t, events.x, events.y, events.p
    latest_word = offset + 2 if per_polarity else offset
    step, step_start, step_end = np.int64(0), np.int64(1), np.int64(0)  # empty: the first event computes its step
    n_out = 0
    for i in range(t.shape[0]):
        xi, yi, ti = np.int64(x[i]), np.int64(y[i]), t[i]
        if xi >= width or yi >= height:
            counts[OUT_OF_BOUNDS] += 1
            continue
        if ti < t0_us:
            counts[BEFORE_T0] += 1
            continue
        if ti >= step_end or ti < step_start:  # a division only when the step changes
            step = (ti - t0_us) // timestep_us
            step_start = t0_us + step * timestep_us
            step_end = step_start + timestep_us
        polarity = 1 if p[i] != 0 else 0
        base = ((yi + pad) * row + xi + pad) * stride
        word = base + offset + (polarity if per_polarity else 0)
        reason = admit(last, word, base + latest_word, ti, step_start, step_end, refractory_us)
        counts[reason] += 1
        if reason == ACCEPTED:
            out_step[n_out] = step
            out_x[n_out], out_y[n_out], out_p[n_out] = xi, yi, polarity
            n_out += 1
    return n_out


class InputFilter:
    """Streaming input process: feed time-ordered event packets, get accepted spikes.

    State is one timestamp per pixel (three with a refractory period per polarity), so
    memory does not grow with the recording.
    """

    def __init__(self, sensor_size: tuple[int, int], t0_us: int, timestep_us: int, refractory_us: int,
                 per_polarity: bool = False):
        width, height = sensor_size
        self.width, self.height = int(width), int(height)
        self.t0_us, self.timestep_us, self.refractory_us = int(t0_us), int(timestep_us), int(refractory_us)
        self.per_polarity = bool(per_polarity)
        self._stride = 3 if self.per_polarity else 1
        self._last = np.full(self.width * self.height * self._stride, NEVER, dtype=np.int64)
        self._counts = np.zeros(5, dtype=np.int64)
        self.events_in = 0

    @property
    def drops(self) -> np.ndarray:
        """Drop counts by slot (``OUT_OF_BOUNDS`` ... ``SAME_STEP``; a view)."""
        return self._counts[:ACCEPTED]

    @property
    def accepted(self) -> int:
        return int(self._counts[ACCEPTED])

    def feed(self, events: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Accepted spikes of ``events``: (input step, x, y, polarity) arrays."""
        n = len(events)
        out_step, out_x, out_y = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
        out_p = np.empty(n, dtype=np.uint8)
        count = filter_events(events, self.width, self.height,
                              self.t0_us, self.timestep_us, self.refractory_us, self.per_polarity,
                              self._last, 0, self.width, self._stride, 0, out_step, out_x, out_y, out_p,
                              self._counts)
        self.events_in += n
        return out_step[:count], out_x[:count], out_y[:count], out_p[:count]


@njit(cache=True)
def first_out_of_order(t, after) -> int:
    """Index of the first time in ``t`` (µs) below its predecessor, or below ``after`` for the
    first one; -1 when ``t`` is in time order."""
    previous = after
    for i in range(t.shape[0]):
        if t[i] < previous:
            return i
        previous = t[i]
    return -1
