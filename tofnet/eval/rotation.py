"""Depth recomputed offline from time-of-travel spikes, with or without rotation (paper eq. 7 vs eq. 8).

A run with ``record_tot=True`` keeps every time-of-travel spike (``TOT_DTYPE``); the
depth neurons' inputs are a pure function of them (docs/semantics.md), so the depth
can be recomputed with any velocity and angular velocity, sampled when wanted:

- ``"network"``: the velocity the network's per-pixel velocity process sends (update
  of step ``s - 1``, sampled at its start); eq. 8 then equals the network's output;
- ``"trigger"``: at the centre of the triggering input step;
- ``"interval"``: averaged over each axis's travel interval, from the centre of the
  facilitating input step to the centre of the triggering one (``A t`` and ``B ω``
  are linear in ``t`` and ``ω``, so averaging those averages the flow).

Used by ``benchmarks/rotation_study.py`` (the study behind eq. 7 in the depth neurons);
``share_split`` is the error-by-translational-share table (``e / r`` law, docs/rotation.md)
and ``split_by_true_share`` gives it for a run's estimates (``tofnet eval``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

import tofnet.numba_cache  # noqa: F401 - before any cached kernel: numba picks its cache key at decoration
from tofnet.events import DEPTH_DTYPE
from tofnet.kernels.depth import float_depth_rotation, signed_axis_count, translational_share
from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.velocity import velocity_term

#: Depth-neuron step minus the tot spike's step, and minus the triggering input step.
TOT_TO_DEPTH_STEPS = 1
INPUT_TO_DEPTH_STEPS = 2
#: Sample points per travel interval for ``when="interval"``.
INTERVAL_SAMPLES = 9
WHENS = ("network", "trigger", "interval")


@dataclass(frozen=True)
class DepthInputs:
    """What each active depth neuron received: its step, pixel and signed counts per axis (steps)."""

    step: np.ndarray
    x: np.ndarray
    y: np.ndarray
    signed_x: np.ndarray
    signed_y: np.ndarray

    def __len__(self) -> int:
        return len(self.step)

    @property
    def measured(self) -> np.ndarray:
        return (self.signed_x != 0) | (self.signed_y != 0)


@njit(cache=True)
def _signed_counts(counts):  # pragma: no cover - numba
    n = counts.shape[0]
    sx = np.empty(n, dtype=np.int64)
    sy = np.empty(n, dtype=np.int64)
    for i in range(n):
        sx[i] = signed_axis_count(counts[i, 0], counts[i, 1])
        sy[i] = signed_axis_count(counts[i, 2], counts[i, 3])
    return sx, sy


def depth_inputs(tot: np.ndarray, width: int) -> DepthInputs:
    """Group time-of-travel spikes (``TOT_DTYPE``) by depth neuron and step; directions ``+u, -u, +v, -v``."""
    key = (tot["step"].astype(np.int64) * 65536 + tot["y"].astype(np.int64)) * width + tot["x"].astype(np.int64)
    unique, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    counts = np.zeros((len(unique), 4), dtype=np.int64)
    counts[inverse, tot["direction"].astype(np.int64)] = tot["count"]  # a unit fires at most once per step
    sx, sy = _signed_counts(counts)
    return DepthInputs(step=tot["step"][first].astype(np.int64) + TOT_TO_DEPTH_STEPS, x=tot["x"][first].copy(),
                       y=tot["y"][first].copy(), signed_x=sx, signed_y=sy)


@njit(cache=True)
def _terms(v, w, x, y, fx, fy, cx, cy):  # pragma: no cover - numba
    n = x.shape[0]
    at = np.empty((n, 2))
    bw = np.empty((n, 2))
    for i in range(n):
        at[i, 0], at[i, 1] = velocity_term(v[i, 0], v[i, 1], v[i, 2], x[i], y[i], fx, fy, cx, cy)
        bw[i, 0], bw[i, 1] = rotational_flow(w[i, 0], w[i, 1], w[i, 2], x[i], y[i], fx, fy, cx, cy)
    return at, bw


@njit(cache=True)
def _depths(sx, sy, at, bw, seconds_per_count):  # pragma: no cover - numba
    n = sx.shape[0]
    z = np.empty(n)
    share = np.empty(n)
    for i in range(n):
        share[i] = translational_share(sx[i], sy[i], bw[i, 0], bw[i, 1], seconds_per_count)
        z[i] = float_depth_rotation(sx[i], sy[i], at[i, 0], at[i, 1], bw[i, 0], bw[i, 1], seconds_per_count)
    return z, share


def _motion(times, x, y, intrinsics, velocity, angular):
    v = np.ascontiguousarray(velocity.velocity_at(times), dtype=np.float64)
    w = np.zeros_like(v) if angular is None else np.ascontiguousarray(angular.angular_velocity_at(times), np.float64)
    k = intrinsics
    return _terms(v, w, x.astype(np.float64), y.astype(np.float64), k.fx, k.fy, k.cx, k.cy)


def recompute_depth(inputs: DepthInputs, *, intrinsics, velocity, angular=None, t0_us: int, timestep_us: int,
                    distance: int = 1, when: str = "trigger") -> tuple[np.ndarray, np.ndarray]:
    """Depth (m) and translational share of every active depth neuron: eq. 7, or eq. 8 when ``angular`` is None.

    ``velocity``: a ``VelocitySource`` (camera frame, m/s); ``angular``: an
    ``AngularVelocitySource`` (rad/s). ``when``: one of ``WHENS`` (module docstring).
    """
    if when not in WHENS:
        raise ValueError(f"when: expected one of {', '.join(WHENS)}, got {when!r}")
    dt = timestep_us * 1e-6
    t0 = t0_us * 1e-6
    trigger = inputs.step - INPUT_TO_DEPTH_STEPS
    if when == "network":
        times = t0 + (inputs.step - 1) * dt
    else:
        times = t0 + (trigger + 0.5) * dt
    at, bw = _motion(times, inputs.x, inputs.y, intrinsics, velocity, angular)
    if when == "interval":
        # Each axis over its own travel interval: the edge left the facilitating pixel |count| steps earlier.
        for axis, signed in ((0, inputs.signed_x), (1, inputs.signed_y)):
            span = np.abs(signed) * dt
            sums_at, sums_bw = np.zeros(len(inputs)), np.zeros(len(inputs))
            for j in range(INTERVAL_SAMPLES):
                frac = j / (INTERVAL_SAMPLES - 1)
                a, b = _motion(times - span * (1 - frac), inputs.x, inputs.y, intrinsics, velocity, angular)
                sums_at += a[:, axis]
                sums_bw += b[:, axis]
            at[:, axis], bw[:, axis] = sums_at / INTERVAL_SAMPLES, sums_bw / INTERVAL_SAMPLES
    return _depths(inputs.signed_x, inputs.signed_y, at, bw, dt / distance)


def as_depth_array(inputs: DepthInputs, z: np.ndarray, keep: np.ndarray, t0_us: int, timestep_us: int) -> np.ndarray:
    """The kept estimates as ``DEPTH_DTYPE`` (stamped at the end of their step, like the backends)."""
    out = np.empty(int(np.count_nonzero(keep)), dtype=DEPTH_DTYPE)
    out["step"] = inputs.step[keep]
    out["t"] = t0_us + (inputs.step[keep] + 1) * timestep_us
    out["x"], out["y"], out["z"] = inputs.x[keep], inputs.y[keep], z[keep]
    return out


#: Translational-share bins of ``share_split``.
SHARE_EDGES = (-math.inf, 0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.1, 1.5, math.inf)


def share_split(share: np.ndarray, rel: np.ndarray, edges=SHARE_EDGES) -> list[dict]:
    """Per share bin: count, median share, median |rel| and signed rel, and median ``|rel| * share``.

    ``rel`` is the signed relative error ``(z - z_gt) / z_gt``. If a timing error ``e``
    becomes ``e / r``, the ``|rel| * share`` column stays near the median ``|e|``.
    """
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (share >= lo) & (share < hi)
        n = int(np.count_nonzero(sel))
        if n == 0:
            rows.append({"lo": lo, "hi": hi, "n": 0, "share": math.nan, "median_rel": math.nan, "bias": math.nan,
                         "rel_times_share": math.nan})
            continue
        rows.append({"lo": lo, "hi": hi, "n": n, "share": float(np.median(share[sel])),
                     "median_rel": float(np.median(np.abs(rel[sel]))), "bias": float(np.median(rel[sel])),
                     "rel_times_share": float(np.median(np.abs(rel[sel] * share[sel])))})
    return rows


def true_share(x, y, z_gt, times, intrinsics, velocity, angular) -> np.ndarray:
    """The true translational share of the image motion at each estimate (dimensionless).

    ``r = ((A t / Z)·f) / (f·f)`` with ``f = A t / Z + B ω`` the true image motion (px/s)
    at pixel ``(x, y)``, true depth ``z_gt`` (m) and time ``times`` (s): the share a depth
    neuron computes when its ``td`` lies along ``f`` (where translation and rotation move
    the image the same way, as in a slide with a pan, for any edge). NaN where the image
    does not move.
    """
    at, bw = _motion(np.asarray(times, dtype=np.float64), np.asarray(x), np.asarray(y), intrinsics, velocity, angular)
    translation = at / np.asarray(z_gt, dtype=np.float64)[:, None]
    flow = translation + bw
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sum(translation * flow, axis=1) / np.sum(flow * flow, axis=1)


def split_by_true_share(recording, depth: np.ndarray, evaluation) -> tuple[list[dict] | None, str]:
    """``share_split`` of an evaluation's matched estimates by their ``true_share``; or None and why not.

    Needs the camera's true motion with its orientation (ground-truth poses, or a simulated
    camera's) and the intrinsics; a camera that does not turn has a share of 1 everywhere.
    """
    from tofnet.io.groundtruth import Trajectory
    from tofnet.io.rotation import PoseAngularVelocity

    motion = recording.trajectory
    if motion is None or recording.intrinsics is None:
        return None, "needs ground-truth poses (groundtruth.txt) and the calibration: the true share needs the motion"
    if hasattr(motion, "angular_velocity_at"):
        angular = motion
    elif isinstance(motion, Trajectory):
        angular = PoseAngularVelocity(motion)
        if not angular.rotates:
            return None, "the camera does not turn: every share is 1"
    else:
        return None, "the ground truth has velocities but no orientations: the true share needs the rotation"
    matches = evaluation.matches
    valid = matches.valid
    times = (evaluation.t0_us + (matches.input_step[valid] + 0.5) * evaluation.timestep_us) * 1e-6
    gt = matches.gt[valid]
    kept = depth[valid]
    share = true_share(kept["x"], kept["y"], gt, times, recording.intrinsics, motion, angular)
    return share_split(share, (kept["z"] - gt) / gt), "true share along the true image motion"


def format_share_split(rows: list[dict], what: str) -> str:
    """The text table ``tofnet eval`` prints: one row per share bin with estimates."""
    lines = [f"error by translational share r ({what}; if a timing error e becomes e / r,",
             "|rel| * r stays flat while |rel| grows as r falls; eq. 8's bias would be r - 1)",
             f"{'r':>14} {'estim.':>8} {'median r':>9} {'med |rel| %':>12} {'bias %':>8} {'|rel|*r %':>10}"]
    for row in rows:
        if row["n"]:
            lines.append(f"{row['lo']:>6g} .. {row['hi']:<4g} {row['n']:8d} {row['share']:9.2f} "
                         f"{100 * row['median_rel']:12.1f} {100 * row['bias']:+8.1f} {100 * row['rel_times_share']:10.1f}")
    return "\n".join(lines)
