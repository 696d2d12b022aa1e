"""The time-of-travel units of an event-driven kernel seen as Algorithm 1's counters (for sessions).

The kernel stores, per unit, the step ``a`` of its last facilitation; Algorithm 1's
counter at the start of step ``now`` is ``now - a`` while that is at most the counter's
maximum, else 0 (overflowed), and 0 for an idle unit (docs/semantics.md).
"""

from __future__ import annotations

import numpy as np

from tofnet.kernels import time_of_travel as tt
from tofnet.kernels.region import TimeOfTravelKernel


def _stamps(kernel: TimeOfTravelKernel) -> np.ndarray:
    """The region's unit stamps, ``[H, W, 4]`` (a view into the kernel's records)."""
    d = kernel.config.units.distance
    h, w = kernel.region.shape
    return kernel._stamp.reshape(h + 4 * d, w + 4 * d, -1)[2 * d:2 * d + h, 2 * d:2 * d + w, :4]


def counters(kernel: TimeOfTravelKernel, now: int) -> tuple[np.ndarray, np.ndarray]:
    """Counters (``[4, H, W]`` int64, steps) and stored polarities (uint8, 0 where idle) at the start of ``now``.

    Every input step before ``now - 1`` must have been given to the kernel.
    """
    tt.flush_pending(kernel._ints, kernel._floats)
    step, polarity = kernel.unit_state()
    counter = np.where(step >= 0, now - step, 0)
    counter[(counter < 1) | (counter > kernel.config.counter_max)] = 0
    polarity = np.where(counter > 0, polarity, 0).astype(np.uint8)
    return np.ascontiguousarray(counter.transpose(2, 0, 1)), np.ascontiguousarray(polarity.transpose(2, 0, 1))


def set_counters(kernel: TimeOfTravelKernel, counter: np.ndarray, polarity: np.ndarray, now: int) -> None:
    """Make the units show ``counter`` (``[4, H, W]``, 0 = idle, at most the counter maximum) with
    ``polarity`` at the start of ``now``."""
    counter = np.asarray(counter, dtype=np.int64)
    tt.flush_pending(kernel._ints, kernel._floats)
    base = int(kernel._cursor[tt.BASE])
    facilitated = now - counter.transpose(1, 2, 0)  # the step a of each running unit
    stamp = ((facilitated - base) << 1) | (np.asarray(polarity).transpose(1, 2, 0) != 0)
    _stamps(kernel)[...] = np.where(counter.transpose(1, 2, 0) > 0, stamp, tt.IDLE).astype(np.int32)
