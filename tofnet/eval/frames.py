"""Scoring estimates against ground truth that comes as frames (depth images, disparity maps).

Each estimate is given the true depth of the frames (``tofnet.io.frames.FrameDepth``) at
its own pixel and the time of the event that triggered it (``tofnet.eval.match``): the
frame nearest in time, or the two around it interpolated (``interpolate``). An estimate
whose event was not found stays unmatched, as with per-event ground truth, so
``matched + unmatched + gt_invalid = estimates`` holds for both. Benchmarks on these datasets
also report the mean absolute error of the pixels nearer than a cut-off (``cutoff_means``).
"""

from __future__ import annotations

import math

import numpy as np

from tofnet.eval.match import Matches

#: Cut-off distances of the mean absolute error (m), as the MVSEC/DSEC/M3ED depth benchmarks report it.
CUTOFFS_M = (10.0, 20.0, 30.0)
#: Their columns (``Evaluation.to_dict``, batch tables).
CUTOFF_COLUMNS = tuple(f"mean_abs_cut{c:g}_m" for c in CUTOFFS_M)


def frame_matches(depth: np.ndarray, matches: Matches, events: np.ndarray, frame_gt, *,
                  interpolate: bool = False) -> Matches:
    """``matches`` with the ground truth of the frames at each estimate's pixel and time (module docstring)."""
    found = matches.found
    gt = np.full(len(depth), np.nan)
    gt[found] = frame_gt.at(events["t"][matches.event_index[found]], depth["x"][found], depth["y"][found],
                            interpolate=interpolate)
    return Matches(gt, matches.event_index, matches.input_step)


def cutoff_means(z: np.ndarray, z_gt: np.ndarray, cutoffs=CUTOFFS_M) -> dict[str, float]:
    """Mean absolute error (m) of the estimates whose true depth is at most each cut-off (NaN without any)."""
    z, z_gt = np.asarray(z, dtype=np.float64), np.asarray(z_gt, dtype=np.float64)
    out = {}
    for cutoff, name in zip(cutoffs, CUTOFF_COLUMNS):
        near = z_gt <= cutoff
        out[name] = float(np.abs(z[near] - z_gt[near]).mean()) if near.any() else math.nan
    return out
