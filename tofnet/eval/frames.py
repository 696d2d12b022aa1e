"""Scoring estimates against ground truth that comes as frames (depth images, disparity maps).

Each estimate is given the true depth of the frames (``tofnet.io.frames.FrameDepth``) at
its own pixel and time: the time of the event that triggered it (``tofnet.eval.match``),
or the middle of its triggering input step when no event was found; the frame nearest in
time, or the two around it interpolated (``interpolate``). Benchmarks on these datasets
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


def frame_matches(depth: np.ndarray, matches: Matches, events: np.ndarray, frame_gt, *, t0_us: int,
                  timestep_us: int, interpolate: bool = False) -> Matches:
    """``matches`` with the ground truth of the frames at each estimate's pixel and time (module docstring)."""
    t = np.int64(t0_us) + matches.input_step * np.int64(timestep_us) + np.int64(timestep_us // 2)
    found = matches.found
    t[found] = events["t"][matches.event_index[found]]
    gt = frame_gt.at(t, depth["x"], depth["y"], interpolate=interpolate)
    return Matches(gt, matches.event_index, matches.input_step)


def cutoff_means(z: np.ndarray, z_gt: np.ndarray, cutoffs=CUTOFFS_M) -> dict[str, float]:
    """Mean absolute error (m) of the estimates whose true depth is at most each cut-off (NaN without any)."""
    z, z_gt = np.asarray(z, dtype=np.float64), np.asarray(z_gt, dtype=np.float64)
    out = {}
    for cutoff, name in zip(cutoffs, CUTOFF_COLUMNS):
        near = z_gt <= cutoff
        out[name] = float(np.abs(z[near] - z_gt[near]).mean()) if near.any() else math.nan
    return out
