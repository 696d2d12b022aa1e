"""Pairing depth estimates with the ground-truth depth of the events that caused them.

An estimate at pixel ``(x, y)`` emitted in output step ``s`` was triggered by the event
the input process accepted at that pixel in input step ``s - latency_steps``
(docs/semantics.md, "Time"). Its ground truth is the ``gt_depth`` of the first event
of that pixel in that input step: the input process forwards at most one event per
pixel and step, the first one, so the others never reached the network.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.errors import DataError

#: Combined (pixel, step) keys must stay below this so int64 arithmetic cannot overflow.
_KEY_LIMIT = 2**62


@dataclass(frozen=True)
class Matches:
    """Per-estimate ground truth, aligned with the depth array it was computed for.

    ``gt`` is the true depth in metres (NaN when there is none); ``event_index`` the
    index of the matched event in the recording (-1 when no event was found);
    ``input_step`` the input step ``s - latency_steps`` that triggered the estimate.
    """

    gt: np.ndarray
    event_index: np.ndarray
    input_step: np.ndarray

    @property
    def found(self) -> np.ndarray:
        """True where an event of the estimate's pixel exists in its input step."""
        return self.event_index >= 0

    @property
    def valid(self) -> np.ndarray:
        """True where the estimate has a usable (finite, positive) ground truth."""
        with np.errstate(invalid="ignore"):
            return np.isfinite(self.gt) & (self.gt > 0)

    @property
    def n_unmatched(self) -> int:
        """Estimates with no event at their pixel in their input step."""
        return int(np.count_nonzero(~self.found))

    @property
    def n_gt_invalid(self) -> int:
        """Estimates whose matched event has a non-finite or non-positive ground truth."""
        return int(np.count_nonzero(self.found & ~self.valid))


def input_steps(t_us: np.ndarray, t0_us: int, timestep_us: int) -> np.ndarray:
    """Input step of each time: ``floor((t - t0) / dt)`` (negative before ``t0``)."""
    if timestep_us <= 0:
        raise DataError(f"timestep must be a positive number of microseconds, got {timestep_us}")
    return (np.asarray(t_us, dtype=np.int64) - np.int64(t0_us)) // np.int64(timestep_us)


def match_estimates(depth: np.ndarray, events: np.ndarray, gt_depth: np.ndarray | None, *,
                    t0_us: int, timestep_us: int, latency_steps: int) -> Matches:
    """Find the ground truth of every estimate (vectorised; no loop per estimate).

    Parameters
    ----------
    depth : ndarray
        Estimates, ``DEPTH_DTYPE`` (``step`` = output step, ``x``/``y`` pixel).
    events : ndarray
        Input events, ``EVENT_DTYPE`` (``t`` in µs), in time order.
    gt_depth : ndarray or None
        True depth of each event in metres, aligned with ``events``; None gives NaN.
    t0_us, timestep_us : int
        Start of step 0 and step length, µs (the run's ``t0`` and ``dt``).
    latency_steps : int
        Output step minus the input step of the triggering event (2 for this network).
    """
    n = len(depth)
    query_step = np.asarray(depth["step"], dtype=np.int64) - np.int64(latency_steps)
    event_index = np.full(n, -1, dtype=np.int64)
    gt = np.full(n, np.nan, dtype=np.float64)
    if n == 0 or len(events) == 0:
        return Matches(gt, event_index, query_step)

    ev_step = input_steps(events["t"], t0_us, timestep_us)
    width = int(max(events["x"].max(), depth["x"].max())) + 1
    ev_pixel = events["y"].astype(np.int64) * width + events["x"].astype(np.int64)
    q_pixel = depth["y"].astype(np.int64) * width + depth["x"].astype(np.int64)

    # One int64 key per (pixel, step); queries outside the events' step range cannot match.
    lo, hi = int(ev_step.min()), int(ev_step.max())
    span = hi - lo + 1
    n_pixels = int(max(ev_pixel.max(), q_pixel.max())) + 1
    if n_pixels * span >= _KEY_LIMIT:
        raise DataError(f"cannot match: {n_pixels} pixels x {span} steps overflows the 64-bit key")
    ev_key = ev_pixel * span + (ev_step - lo)
    in_range = (query_step >= lo) & (query_step <= hi)
    q_key = q_pixel * span + (np.clip(query_step, lo, hi) - lo)

    # A stable sort keeps events of one (pixel, step) in time order, so the first of
    # each run of equal keys is the event the input process would have accepted.
    order = np.argsort(ev_key, kind="stable")
    sorted_key = ev_key[order]
    first = np.empty(len(sorted_key), dtype=bool)
    first[0] = True
    np.not_equal(sorted_key[1:], sorted_key[:-1], out=first[1:])
    unique_key, first_event = sorted_key[first], order[first]

    pos = np.searchsorted(unique_key, q_key)
    pos_clipped = np.minimum(pos, len(unique_key) - 1)
    hit = in_range & (pos < len(unique_key)) & (unique_key[pos_clipped] == q_key)
    event_index[hit] = first_event[pos_clipped[hit]]
    if gt_depth is not None:
        gt[hit] = np.asarray(gt_depth, dtype=np.float64)[event_index[hit]]
    return Matches(gt, event_index, query_step)
