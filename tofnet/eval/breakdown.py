"""Coverage and error by true-depth band and by motion phase.

An estimator can be accurate overall and still answer only the near surfaces, or only
while the camera moves steadily. These tables split both coverage and error:

- by the **true depth** of the input events (``DEPTH_BANDS``, metres): a band's coverage is
  the estimates whose triggering event lies in the band over the band's events;
- by the **motion phase** at the event's time: ``reversal`` where the camera's translation
  turned by more than 90 degrees within the last ``REVERSAL_WINDOW_S`` (its direction at
  ``t`` against every sampled direction in ``[t - window, t]``) or its speed is below
  ``SLOW_SHARE`` of the recording's median speed; ``steady`` elsewhere. The velocity is
  the recording's ground truth (poses), sampled every ``PHASE_STEP_S``.

Only estimates with a usable ground truth enter a group (``Matches.valid``); events
without one are in no band. docs/evaluation.md has the definitions with an example.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tofnet.eval.match import Matches
from tofnet.eval.metrics import ErrorStats, _number
from tofnet.units import bounded_windows

#: Band edges of the true depth, metres: < 1, 1-2, 2-4, 4-8, >= 8.
DEPTH_BANDS = (0.0, 1.0, 2.0, 4.0, 8.0, math.inf)
#: Look-back of the reversal test, seconds (reversals every 100-300 ms leave surfaces this old).
REVERSAL_WINDOW_S = 0.1
#: Below this share of the median translational speed the motion counts as a reversal.
SLOW_SHARE = 0.25
#: Velocity sampling of the phase labels, seconds.
PHASE_STEP_S = 0.001
#: Most cells of ``PHASE_STEP_S`` in a motion-phase grid: 28 hours of a recording (a few GB while it is scored).
MAX_PHASE_CELLS = 100_000_000
PHASES = ("steady", "reversal")


@dataclass(frozen=True)
class GroupStats:
    """Coverage and error of the estimates whose triggering event is in one group."""

    label: str
    events: int
    estimates: int
    coverage: float
    errors: ErrorStats

    def to_dict(self) -> dict:
        return {"group": self.label, "events": self.events, "estimates": self.estimates,
                "coverage": _number(self.coverage), **self.errors.to_dict()}


def band_label(lo: float, hi: float) -> str:
    if lo <= 0:
        return f"< {hi:g} m"
    if math.isinf(hi):
        return f">= {lo:g} m"
    return f"{lo:g}-{hi:g} m"


def _groups(labels: list[str], event_group: np.ndarray, estimate_group: np.ndarray, z: np.ndarray,
            gt: np.ndarray) -> list[GroupStats]:
    out = []
    for i, label in enumerate(labels):
        n_events = int(np.count_nonzero(event_group == i))
        mine = estimate_group == i
        n = int(np.count_nonzero(mine))
        out.append(GroupStats(label, n_events, n, n / n_events if n_events else math.nan, ErrorStats.of(z[mine], gt[mine])))
    return out


def by_depth_band(depth: np.ndarray, matches: Matches, gt_depth: np.ndarray,
                  edges: tuple[float, ...] = DEPTH_BANDS) -> list[GroupStats]:
    """Coverage and error per band of true depth (``edges`` in metres)."""
    gt_depth = np.asarray(gt_depth, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        usable = np.isfinite(gt_depth) & (gt_depth > 0)
    event_band = np.where(usable, np.searchsorted(edges, np.where(usable, gt_depth, 0.0), side="right") - 1, -1)
    valid = matches.valid
    z, gt = np.asarray(depth["z"], dtype=np.float64)[valid], matches.gt[valid]
    estimate_band = np.searchsorted(edges, gt, side="right") - 1
    labels = [band_label(lo, hi) for lo, hi in zip(edges[:-1], edges[1:])]
    return _groups(labels, event_band, estimate_band, z, gt)


def motion_phase(trajectory, t_s: np.ndarray) -> np.ndarray:
    """Phase of each time ``t_s`` (seconds): 0 steady, 1 reversal (module docstring)."""
    t_s = np.asarray(t_s, dtype=np.float64)
    if t_s.size == 0:
        return np.zeros(0, dtype=np.int8)
    lo, hi = float(t_s.min()) - REVERSAL_WINDOW_S, float(t_s.max())
    # The grid ends at the last event: a trajectory stands still after its end, which is no reversal. Its size is
    # counted before it is made (a recording's events may span 2**61 µs).
    cells = bounded_windows(int(math.ceil((hi - lo) / PHASE_STEP_S)), round(PHASE_STEP_S * 1e6),
                            f"the events, over {hi - lo:.6g} s,", "score a time window (--start/--duration)",
                            MAX_PHASE_CELLS, unit="motion-phase cells")
    grid = np.linspace(lo, hi, cells + 1)
    spacing = (hi - lo) / max(len(grid) - 1, 1)
    velocity = np.asarray(trajectory.velocity_at(grid), dtype=np.float64)
    speed = np.linalg.norm(velocity, axis=1)
    slow = speed < SLOW_SHARE * float(np.median(speed))
    direction = velocity / np.maximum(speed, 1e-12)[:, None]
    look_back = int(round(REVERSAL_WINDOW_S / spacing)) if spacing > 0 else 0
    turned = np.zeros(len(grid), dtype=bool)
    for lag in range(1, look_back + 1):  # one pass per lag, vectorised over the grid
        turned[lag:] |= np.einsum("ij,ij->i", direction[lag:], direction[:-lag]) < 0
    phase = (slow | turned).astype(np.int8)
    index = np.clip(np.floor((t_s - lo) / spacing).astype(np.int64), 0, len(grid) - 1) if spacing > 0 else \
        np.full(t_s.shape, len(grid) - 1)
    return phase[index]


def by_motion_phase(depth: np.ndarray, matches: Matches, events: np.ndarray, trajectory) -> list[GroupStats]:
    """Coverage and error per motion phase (the trajectory's clock is the events' ``t`` in seconds)."""
    event_phase = motion_phase(trajectory, np.asarray(events["t"], dtype=np.float64) * 1e-6)
    valid = matches.valid
    z, gt = np.asarray(depth["z"], dtype=np.float64)[valid], matches.gt[valid]
    estimate_phase = event_phase[matches.event_index[valid]]
    return _groups(list(PHASES), event_phase, estimate_phase, z, gt)


def format_groups(title: str, groups: list[GroupStats]) -> str:
    """A small text table: events, estimates, coverage, median and signed error per group."""
    lines = [title, f"{'':>12} {'events':>9} {'estim.':>9} {'cover %':>8} {'med [%]':>8} {'bias [%]':>9}"]
    for g in groups:
        cover = f"{g.coverage * 100:8.2f}" if math.isfinite(g.coverage) else f"{'-':>8}"
        med = f"{g.errors.median_rel_pct:8.2f}" if g.errors.n else f"{'-':>8}"
        bias = f"{g.errors.bias_rel_pct:+9.2f}" if g.errors.n else f"{'-':>9}"
        lines.append(f"{g.label:>12} {g.events:9d} {g.estimates:9d} {cover} {med} {bias}")
    return "\n".join(lines)


def _key(label: str) -> str:
    return label.replace("< ", "lt").replace(">= ", "ge").replace("-", "to").replace(" ", "")


#: Flat column names of ``breakdown_columns`` (batch tables): coverage and median error per group.
BREAKDOWN_COLUMNS = tuple(f"{what}_{_key(label)}_pct" for label in
                          [band_label(lo, hi) for lo, hi in zip(DEPTH_BANDS[:-1], DEPTH_BANDS[1:])] + list(PHASES)
                          for what in ("coverage", "median_rel"))


def breakdown_columns(depth: np.ndarray, matches: Matches, recording) -> dict:
    """``BREAKDOWN_COLUMNS`` of one run on a recording with per-event ground truth (None where undefined)."""
    groups = by_depth_band(depth, matches, recording.gt_depth)
    if recording.trajectory is not None:
        groups += by_motion_phase(depth, matches, recording.events, recording.trajectory)
    out = dict.fromkeys(BREAKDOWN_COLUMNS)
    for g in groups:
        out[f"coverage_{_key(g.label)}_pct"] = _number(100.0 * g.coverage)
        out[f"median_rel_{_key(g.label)}_pct"] = _number(g.errors.median_rel_pct) if g.errors.n else None
    return out
