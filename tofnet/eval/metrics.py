"""Accuracy of depth estimates against per-event ground truth (paper §5, Tables 1-2).

Errors are those of the paper: mean and median absolute error ``|z - z_gt|`` in metres
and mean and median relative error ``|z - z_gt| / z_gt`` in percent, over every
estimate with a usable ground truth. Coverage is the share of input events answered
by an estimate. Windows split the recording by the time of the triggering input step,
so an estimate and the event that caused it always fall in the same window.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from tofnet.errors import DataError
from tofnet.eval.match import Matches, input_steps, match_estimates
from tofnet.units import format_seconds, seconds_of

#: Metadata a depth file must carry to be matched to its input events.
TIMING_KEYS = ("t0_us", "timestep_us", "latency_steps")
#: Default length of the per-window metrics, seconds.
DEFAULT_WINDOW_S = 0.1


def _number(value: float) -> float | None:
    """JSON has no NaN: an undefined metric becomes ``null``."""
    return None if value is None or not math.isfinite(value) else float(value)


@dataclass(frozen=True)
class ErrorStats:
    """Error of ``n`` estimates: absolute in metres, relative in percent (NaN when ``n == 0``).

    ``bias_rel_pct`` is the median *signed* relative error ``(z - z_gt) / z_gt``: not in
    the paper, but it tells a systematic under- or overestimate from scatter.
    """

    n: int
    mean_abs_m: float
    median_abs_m: float
    mean_rel_pct: float
    median_rel_pct: float
    bias_rel_pct: float = math.nan

    @classmethod
    def of(cls, z: np.ndarray, z_gt: np.ndarray) -> "ErrorStats":
        """Statistics of estimates ``z`` against true depths ``z_gt`` (both metres, ``z_gt > 0``)."""
        if len(z) == 0:
            return cls(0, math.nan, math.nan, math.nan, math.nan, math.nan)
        signed = np.asarray(z, dtype=np.float64) - z_gt
        abs_err = np.abs(signed)
        rel_err = abs_err / z_gt * 100.0
        return cls(int(len(z)), float(abs_err.mean()), float(np.median(abs_err)),
                   float(rel_err.mean()), float(np.median(rel_err)), float(np.median(signed / z_gt)) * 100.0)

    def to_dict(self) -> dict:
        return {"matched": self.n, "mean_abs_m": _number(self.mean_abs_m), "median_abs_m": _number(self.median_abs_m),
                "mean_rel_pct": _number(self.mean_rel_pct), "median_rel_pct": _number(self.median_rel_pct),
                "bias_rel_pct": _number(self.bias_rel_pct)}


@dataclass(frozen=True)
class WindowStats:
    """Metrics of one window ``[start_s, end_s)``, seconds since ``t0``."""

    start_s: float
    end_s: float
    events_in: int
    estimates: int
    unmatched: int
    coverage: float
    errors: ErrorStats

    def to_dict(self) -> dict:
        return {"start_s": self.start_s, "end_s": self.end_s, "events_in": self.events_in,
                "estimates": self.estimates, "unmatched": self.unmatched,
                "coverage": _number(self.coverage), **self.errors.to_dict()}


@dataclass
class Evaluation:
    """Accuracy of one run on one recording, overall and per window.

    ``coverage = estimates / events_in``; ``unmatched`` estimates found no event at
    their pixel in their input step; ``gt_invalid`` found one whose ground truth is not
    a positive finite depth. Neither enters the errors, both are reported.
    """

    source: str
    events_in: int
    estimates: int
    unmatched: int
    gt_invalid: int
    coverage: float
    errors: ErrorStats
    window_s: float
    windows: list[WindowStats]
    t0_us: int
    timestep_us: int
    latency_steps: int
    matches: Matches | None = field(default=None, repr=False, compare=False)
    ground_truth: str = "per event"
    cutoffs: dict = field(default_factory=dict)

    @property
    def matched(self) -> int:
        """Estimates that entered the error statistics."""
        return self.errors.n

    def to_dict(self) -> dict:
        """Plain data for JSON (undefined metrics are ``None``)."""
        return {"source": self.source, "events_in": self.events_in, "estimates": self.estimates,
                "matched": self.matched, "unmatched": self.unmatched, "gt_invalid": self.gt_invalid,
                "coverage": _number(self.coverage), **self.errors.to_dict(),
                **{k: _number(v) for k, v in self.cutoffs.items()}, "ground_truth": self.ground_truth,
                "t0_us": self.t0_us, "timestep_s": seconds_of(self.timestep_us),
                "latency_steps": self.latency_steps, "window_s": self.window_s,
                "windows": [w.to_dict() for w in self.windows]}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, allow_nan=False)

    def table(self, *, windows: bool = True) -> str:
        """A readable text report: totals, the paper's four errors, then one row per window."""
        dt = seconds_of(self.timestep_us)
        lines = [f"source        {self.source}",
                 f"ground truth  {self.ground_truth}",
                 f"timing        step {format_seconds(dt)}, latency {self.latency_steps} steps "
                 f"({format_seconds(self.latency_steps * dt)})",
                 f"events in     {self.events_in:>10d}",
                 f"estimates     {self.estimates:>10d}   coverage {_pct(self.coverage)}",
                 f"matched       {self.matched:>10d}",
                 f"unmatched     {self.unmatched:>10d}   (no event at the pixel in input step s-{self.latency_steps})",
                 f"gt invalid    {self.gt_invalid:>10d}   ("
                 + ("matched event without a positive finite depth)" if self.ground_truth == "per event" else
                    "no positive finite depth in the frames at the estimate's pixel and time)"),
                 "",
                 f"{'':14}{'mean':>10}{'median':>10}",
                 f"{'abs error [m]':14}{_fmt(self.errors.mean_abs_m, 3)}{_fmt(self.errors.median_abs_m, 3)}",
                 f"{'rel error [%]':14}{_fmt(self.errors.mean_rel_pct, 2)}{_fmt(self.errors.median_rel_pct, 2)}",
                 f"{'bias [%]':14}{'':10}{_fmt(self.errors.bias_rel_pct, 2)}   (signed: (z - z_gt) / z_gt)"]
        if self.cutoffs:
            lines.append("mean abs error [m] of true depths up to " + ", ".join(
                f"{name.removeprefix('mean_abs_cut').removesuffix('_m')} m: {_fmt(v, 3, 0)}"
                for name, v in self.cutoffs.items()))
        if windows and self.windows:
            lines += ["", f"per window of {format_seconds(self.window_s)} (seconds since t0; "
                          f"estimates counted at their triggering input step)",
                      f"{'window [s]':>17} {'events':>8} {'estim.':>8} {'cover %':>8} {'matched':>8}"
                      f" {'mean [m]':>9} {'med [m]':>9} {'mean [%]':>9} {'med [%]':>9}"]
            for w in self.windows:
                e = w.errors
                lines.append(f"{w.start_s:8.3f}-{w.end_s:<8.3f} {w.events_in:8d} {w.estimates:8d}"
                             f" {_fmt(w.coverage * 100 if math.isfinite(w.coverage) else math.nan, 2, 8)}"
                             f" {e.n:8d}{_fmt(e.mean_abs_m, 3)}{_fmt(e.median_abs_m, 3)}"
                             f"{_fmt(e.mean_rel_pct, 2)}{_fmt(e.median_rel_pct, 2)}")
        return "\n".join(lines)


def _fmt(value: float, digits: int, width: int = 10) -> str:
    return f"{'-':>{width}}" if not math.isfinite(value) else f"{value:{width}.{digits}f}"


def _pct(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value * 100:.2f} %"


def evaluate_arrays(depth: np.ndarray, events: np.ndarray, gt_depth: np.ndarray, *, t0_us: int,
                    timestep_us: int, latency_steps: int, window_s: float = DEFAULT_WINDOW_S,
                    source: str = "<memory>", frame_gt=None, interpolate: bool = False) -> Evaluation:
    """Match ``depth`` (``DEPTH_DTYPE``) to ``events`` and their ``gt_depth`` (m) and compute metrics.

    ``window_s`` is the length of the per-window metrics in seconds, windows starting
    at ``t0_us``; 0 or less gives no windows. With ``frame_gt`` (``tofnet.io.frames.FrameDepth``)
    each estimate is scored against the frames at its own pixel and time (``tofnet.eval.frames``;
    ``interpolate``: the two frames around it) instead of its event's ``gt_depth``.
    """
    from tofnet.eval.frames import cutoff_means, frame_matches

    matches = match_estimates(depth, events, gt_depth, t0_us=t0_us, timestep_us=timestep_us,
                              latency_steps=latency_steps)
    what = "per event"
    if frame_gt is not None:
        matches = frame_matches(depth, matches, events, frame_gt, interpolate=interpolate)
        what = f"{len(frame_gt)} {frame_gt.what} ({'interpolated' if interpolate else 'nearest'} in time)"
    valid = matches.valid
    errors = ErrorStats.of(depth["z"][valid], matches.gt[valid])
    events_in = int(len(events))
    coverage = len(depth) / events_in if events_in else math.nan
    windows = _windows(depth, events, matches, t0_us, timestep_us, window_s) if window_s > 0 else []
    return Evaluation(source=source, events_in=events_in, estimates=int(len(depth)),
                      unmatched=matches.n_unmatched, gt_invalid=matches.n_gt_invalid, coverage=coverage,
                      errors=errors, window_s=float(window_s), windows=windows, t0_us=int(t0_us),
                      timestep_us=int(timestep_us), latency_steps=int(latency_steps), matches=matches,
                      ground_truth=what, cutoffs=cutoff_means(depth["z"][valid], matches.gt[valid]))


def evaluate(recording, depth: np.ndarray, meta: dict, *, window_s: float = DEFAULT_WINDOW_S,
             interpolate: bool = False) -> Evaluation:
    """Metrics of ``depth`` (with its ``meta``: ``t0_us``, ``timestep_us``, ``latency_steps``) on a ``Recording``;
    against its ground-truth frames when it has them (``frame_gt``; ``interpolate`` in time)."""
    if recording.gt_depth is None:
        raise DataError(f"{recording.source}: no ground-truth depth, per event (events_depth.npy beside an ECD "
                        "folder's events, or in a .npz tofnet wrote: `tofnet simulate` and `tofnet convert` to those "
                        "keep it; RAW, DAT, Event Stream, AEDAT4 and HDF5 have no place for it) or as frames "
                        "(a DSEC, MVSEC, M3ED or EVIMO2 sequence); eval needs one")
    meta = require_timing(meta)
    return evaluate_arrays(depth, recording.events, recording.gt_depth, t0_us=int(meta["t0_us"]),
                           timestep_us=int(meta["timestep_us"]), latency_steps=int(meta["latency_steps"]),
                           window_s=window_s, source=recording.source,
                           frame_gt=getattr(recording, "frame_gt", None), interpolate=interpolate)


def require_timing(meta: dict) -> dict:
    """``meta`` if it has ``t0_us``, ``timestep_us`` and ``latency_steps``, else a ``DataError``."""
    missing = [key for key in TIMING_KEYS if meta.get(key) is None]
    if missing:
        raise DataError(f"the depth file lacks {', '.join(missing)} (a .csv holds no timing); "
                        f"evaluate the .npz written by `tofnet run`, or give --timestep and --latency-steps")
    return meta


def window_index(t_rel_us: np.ndarray, window_us: int) -> np.ndarray:
    """Window of each time since ``t0`` (µs); negative before ``t0``."""
    return np.asarray(t_rel_us, dtype=np.int64) // np.int64(window_us)


def _windows(depth: np.ndarray, events: np.ndarray, matches: Matches, t0_us: int, timestep_us: int,
             window_s: float) -> list[WindowStats]:
    window_us = max(1, int(round(window_s * 1e6)))
    ev_win = window_index(input_steps(events["t"], t0_us, timestep_us) * timestep_us, window_us)
    est_win = window_index(matches.input_step * timestep_us, window_us)
    last_event, last_estimate = (int(w.max()) if len(w) else -1 for w in (ev_win, est_win))
    last = max(last_event, last_estimate)
    if last < 0:
        return []
    from tofnet.units import MAX_METRIC_WINDOWS, bounded_windows, format_seconds
    what = (f"the estimates (array 'step' to {int(depth['step'].max())})"
            if last_estimate >= last_event else "the recording's events")
    n_win = bounded_windows(last + 1, window_us, f"per-window metrics: {what}, reaching "
                            f"{format_seconds(last * window_us * 1e-6)} after t0,", "give a longer --window "
                            "(0: none) or a time window (--start/--duration)", MAX_METRIC_WINDOWS)
    # Times before t0 belong to no window; bincount needs non-negative indices.
    events_per = np.bincount(ev_win[ev_win >= 0], minlength=n_win)
    in_win = est_win >= 0
    estimates_per = np.bincount(est_win[in_win], minlength=n_win)
    unmatched_per = np.bincount(est_win[in_win & ~matches.found], minlength=n_win)

    valid = matches.valid & in_win
    z, gt, win = depth["z"][valid], matches.gt[valid], est_win[valid]
    order = np.argsort(win, kind="stable")
    z, gt, win = z[order], gt[order], win[order]
    bounds = np.searchsorted(win, np.arange(n_win + 1))
    out = []
    for i in range(n_win):  # one iteration per window, not per estimate
        a, b = bounds[i], bounds[i + 1]
        n_events = int(events_per[i])
        out.append(WindowStats(start_s=i * window_us * 1e-6, end_s=(i + 1) * window_us * 1e-6,
                               events_in=n_events, estimates=int(estimates_per[i]),
                               unmatched=int(unmatched_per[i]),
                               coverage=estimates_per[i] / n_events if n_events else math.nan,
                               errors=ErrorStats.of(z[a:b], gt[a:b])))
    return out
