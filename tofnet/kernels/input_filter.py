"""The input process: refractory filter, one event per pixel per step, counted drops."""

from __future__ import annotations

import numpy as np
from numba import njit

from tofnet.backends.base import DROP_REASONS

# Indices into the drop counter array, in DROP_REASONS order.
OUT_OF_BOUNDS, BEFORE_T0, REFRACTORY, SAME_STEP = range(4)
assert DROP_REASONS == ("out_of_bounds", "before_t0", "refractory", "same_step")

_NEVER = np.int64(-(1 << 62))  # "no event yet": far enough back that any refractory has passed


@njit(cache=True)
def _filter(t, x, y, p, width, height, t0_us, timestep_us, refractory_us, per_polarity,
            last_t, last_step, out_step, out_x, out_y, out_p, drops):
    n_out = 0
    for i in range(t.shape[0]):
        xi = np.int64(x[i])
        yi = np.int64(y[i])
        if xi >= width or yi >= height:
            drops[OUT_OF_BOUNDS] += 1
            continue
        ti = t[i]
        if ti < t0_us:
            drops[BEFORE_T0] += 1
            continue
        channel = np.int64(p[i]) if per_polarity else 0
        if ti - last_t[yi, xi, channel] < refractory_us:
            drops[REFRACTORY] += 1
            continue
        step = (ti - t0_us) // timestep_us
        if last_step[yi, xi] == step:
            drops[SAME_STEP] += 1
            continue
        last_t[yi, xi, channel] = ti
        last_step[yi, xi] = step
        out_step[n_out] = step
        out_x[n_out] = xi
        out_y[n_out] = yi
        out_p[n_out] = p[i]
        n_out += 1
    return n_out


class InputFilter:
    """Streaming input process: feed time-ordered event packets, get accepted spikes.

    State is one timestamp and one step per pixel (and polarity, when the refractory
    period is per polarity), so memory does not grow with the recording.
    """

    def __init__(self, sensor_size: tuple[int, int], t0_us: int, timestep_us: int, refractory_us: int,
                 per_polarity: bool = False):
        width, height = sensor_size
        self.width, self.height = width, height
        self.t0_us, self.timestep_us, self.refractory_us = int(t0_us), int(timestep_us), int(refractory_us)
        self.per_polarity = bool(per_polarity)
        self._last_t = np.full((height, width, 2), _NEVER, dtype=np.int64)
        self._last_step = np.full((height, width), -1, dtype=np.int64)
        self.drops = np.zeros(len(DROP_REASONS), dtype=np.int64)
        self.events_in = 0
        self.accepted = 0

    def feed(self, events: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Accepted spikes of ``events``: (input step, x, y, polarity) arrays."""
        n = len(events)
        out_step = np.empty(n, dtype=np.int64)
        out_x = np.empty(n, dtype=np.int64)
        out_y = np.empty(n, dtype=np.int64)
        out_p = np.empty(n, dtype=np.uint8)
        count = _filter(events["t"], events["x"], events["y"], events["p"], self.width, self.height,
                        self.t0_us, self.timestep_us, self.refractory_us, self.per_polarity,
                        self._last_t, self._last_step, out_step, out_x, out_y, out_p, self.drops)
        self.events_in += n
        self.accepted += count
        return out_step[:count], out_x[:count], out_y[:count], out_p[:count]

    @property
    def dropped(self) -> dict[str, int]:
        return {reason: int(c) for reason, c in zip(DROP_REASONS, self.drops)}
