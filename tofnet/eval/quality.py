"""Error and coverage against a threshold on the estimates' fit quality: density against accuracy.

A time-surface estimate comes with the fit behind it (``time_surface_quality`` records,
aligned with the depth records): the points the fit kept and their rms distance from it
(px). Keeping only estimates whose rms is at most ``τ`` (or whose support is at least ``n``
points) trades coverage for accuracy; ``quality_curve`` measures that trade on a recording
with ground truth, one row per threshold, so a user can choose where to cut.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tofnet.errors import DataError
from tofnet.eval.match import Matches
from tofnet.eval.metrics import ErrorStats, _number

#: Quality fields a curve can be drawn on: field -> (keep rule, unit). ``max``: keep ``value <= τ``.
CRITERIA = {"rms_px": ("max", "px"), "points": ("min", "points")}
#: Default rms thresholds, px (the estimator's own limit, ``max_rms_px``, is 0.25 by default).
RMS_THRESHOLDS = (0.05, 0.075, 0.1, 0.125, 0.15, 0.175, 0.2, 0.25, math.inf)
#: Default support thresholds, points.
POINT_THRESHOLDS = (0, 8, 10, 12, 14, 16, 20, 24, 30)


@dataclass(frozen=True)
class CurvePoint:
    """Estimates kept at one threshold, their coverage (per input event) and error."""

    threshold: float
    kept: int
    coverage: float
    errors: ErrorStats

    def to_dict(self) -> dict:
        return {"threshold": _number(self.threshold), "kept": self.kept, "coverage": _number(self.coverage),
                **self.errors.to_dict()}


def check_aligned(depth: np.ndarray, quality: np.ndarray, source: str) -> None:
    """A ``DataError`` unless ``quality`` has one record per depth record, same step and pixel."""
    names = quality.dtype.names or ()
    missing = [f for f in ("step", "x", "y", *CRITERIA) if f not in names]
    if missing:
        raise DataError(f"{source}: not a fit-quality file (no {', '.join(missing)}); expected the "
                        f"*.quality.npz that `tofnet run` writes beside the depth")
    if len(quality) != len(depth) or not all(np.array_equal(quality[f], depth[f]) for f in ("step", "x", "y")):
        raise DataError(f"{source}: its {len(quality)} records are not those of the depth file's {len(depth)} "
                        f"estimates (same step and pixel, same order); was it written by the same run?")


def quality_curve(depth: np.ndarray, quality: np.ndarray, matches: Matches, events_in: int,
                  criterion: str = "rms_px", thresholds: tuple[float, ...] | None = None) -> list[CurvePoint]:
    """Coverage and error of the estimates kept at each threshold on ``criterion`` (``CRITERIA``)."""
    if criterion not in CRITERIA:
        raise DataError(f"quality criterion: expected one of {', '.join(CRITERIA)}, got {criterion!r}")
    rule, _ = CRITERIA[criterion]
    if thresholds is None:
        thresholds = RMS_THRESHOLDS if criterion == "rms_px" else POINT_THRESHOLDS
    value = np.asarray(quality[criterion])
    valid = matches.valid
    z = np.asarray(depth["z"], dtype=np.float64)
    out = []
    for tau in thresholds:
        # In the field's own type: a threshold written as 0.05 keeps an rms stored as float32(0.05).
        tau_typed = value.dtype.type(tau) if value.dtype.kind == "f" else tau
        kept = value <= tau_typed if rule == "max" else value >= tau_typed
        use = kept & valid
        out.append(CurvePoint(float(tau), int(np.count_nonzero(kept)),
                              np.count_nonzero(kept) / events_in if events_in else math.nan,
                              ErrorStats.of(z[use], matches.gt[use])))
    return out


def format_curve(criterion: str, curve: list[CurvePoint]) -> str:
    rule, unit = CRITERIA[criterion]
    keep = f"{criterion} <= τ" if rule == "max" else f"{criterion} >= τ"
    lines = [f"by fit quality (estimates with {keep}; coverage per input event)",
             f"{'τ [' + unit + ']':>12} {'kept':>9} {'cover %':>8} {'med [%]':>8} {'mean [%]':>9} {'bias [%]':>9}"]
    for p in curve:
        e = p.errors
        cells = [f"{p.coverage * 100:8.2f}" if math.isfinite(p.coverage) else f"{'-':>8}"]
        cells += [f"{v:8.2f}" if e.n else f"{'-':>8}" for v in (e.median_rel_pct,)]
        cells += [f"{v:9.2f}" if e.n else f"{'-':>9}" for v in (e.mean_rel_pct,)]
        cells += [f"{e.bias_rel_pct:+9.2f}" if e.n else f"{'-':>9}"]
        lines.append(f"{p.threshold:>12g} {p.kept:9d} " + " ".join(cells))
    return "\n".join(lines)


def read_quality(path) -> np.ndarray:
    """The fit-quality records of a ``*.quality.npz`` written by ``tofnet run``, as one structured array."""
    from tofnet.io.npy import load_npz

    keys, arrays = load_npz(path, what="quality file")
    wanted = ("step", "x", "y", *CRITERIA)
    missing = [k for k in wanted if k not in keys]
    if missing:
        raise DataError(f"{path}: not a fit-quality file (no {', '.join(missing)}); expected the *.quality.npz "
                        f"that `tofnet run` writes beside the depth")
    n = len(arrays["step"])
    if any(len(arrays[k]) != n or arrays[k].ndim != 1 for k in keys):
        raise DataError(f"{path}: its columns differ in length; expected one record per estimate")
    records = np.empty(n, dtype=[(k, arrays[k].dtype) for k in keys])
    for k in keys:
        records[k] = arrays[k]
    return records


def quality_beside(depth_path) -> Path | None:
    """The one ``<stem>.*.quality.npz`` beside a depth file (what ``tofnet run`` writes), or None."""
    depth_path = Path(depth_path)
    found = sorted(depth_path.parent.glob(f"{depth_path.stem}.*.quality.npz"))
    return found[0] if len(found) == 1 else None
