"""Comparing two runs of one case: exact for integer backends, with stated tolerances otherwise.

Whatever the arithmetic, the integer parts of a network must agree exactly: every
process's counts (apart from the rejections below), every output that is not a depth,
and which depth neurons were reached. Depth outputs then compare by mode:

``exact``  (fixed vs fixed): every record of every output bit for bit, every count.
``float``  (float vs float): the same ``(t, x, y, step)`` set and counts, ``z`` within
           ``FLOAT_RTOL`` relative; float fields of other outputs likewise.
``quantised`` (fixed vs float), for the outputs of processes that read counter spikes
           (the depth process): ``|z_fixed - z_float| <= (|m_x| + |m_y|) * 2**-(F+1)``
           (docs/fixed_point.md, ``tofnet.kernels.fixed_point.depth_tolerance``), where
           ``m_x, m_y`` are the estimate's signed counts (read off the probed spikes of the
           time-of-travel process feeding it; the largest counts when not probed); an
           estimate may be missing on one side only when its depth is within that
           tolerance of its process's ``min_depth`` or ``max_depth``, and that process's
           rejection counts must differ by exactly those estimates. A depth process with
           ``b_w`` connected (eq. 7) is held to ``rotation_depth_tolerance`` instead, its
           share computed from the counts and the probed angular velocity updates (the
           runner probes them; ``recording`` gives the intrinsics); estimates may then also
           flip at ``min_share``. Depth outputs of other
           processes (e.g. a user's filter downstream) have no stated bound and are listed
           in ``Comparison.notes`` instead; their counts may differ.

Outputs are compared in the canonical order (step, then y, then x), which every
backend produces. What a user reads off a result is compared too (``visible_differences``):
each output's payload, each process's declared counts and the run summary (events in,
accepted, drops, totals, latency, steps; in ``quantised`` mode but for what follows from the
estimates, compared above within the tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.lib.recfunctions import repack_fields

from tofnet.conformance.visible import ESTIMATE_KEYS, visible_differences
from tofnet.core.network import Network
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, depth_tolerance, quantize, rotation_depth_tolerance
from tofnet.kernels.rotation import rotational_flow

#: Relative tolerance on float fields between two float backends.
FLOAT_RTOL = 1e-9
#: Run facts every pair of backends must agree on exactly.
EXACT_FIELDS = ("steps", "t0_us", "timestep_us")
MODES = ("exact", "float", "quantised")


def mode_of(arithmetic: str, baseline_arithmetic: str) -> str:
    """``exact`` for two fixed backends, ``float`` for two float ones, else ``quantised``."""
    if arithmetic == baseline_arithmetic:
        return "exact" if arithmetic == "fixed" else "float"
    return "quantised"


@dataclass
class Comparison:
    """The outcome of comparing a result with its baseline: the differences found, in order."""

    mode: str
    differences: list[str] = field(default_factory=list)
    estimates: tuple[int, int] = (0, 0)
    #: Outputs this mode states no bound for (left uncompared), with why.
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.differences

    @property
    def first(self) -> str:
        return self.differences[0] if self.differences else ""


def sort_depth(depth: np.ndarray) -> np.ndarray:
    """Estimates by step, then y, then x (the canonical order)."""
    return depth[np.lexsort((depth["x"], depth["y"], depth["step"]))]


def sort_tot(tot: np.ndarray) -> np.ndarray:
    return tot[np.lexsort((tot["direction"], tot["x"], tot["y"], tot["step"]))]


def compare(result, baseline, mode: str, network: Network, recording=None) -> Comparison:
    """Compare ``result`` with ``baseline`` (``RunResult``s of one case on ``network``) in ``mode``.

    ``recording``: the case's recording, whose intrinsics a depth process with ``b_w``
    needs in ``quantised`` mode when its angular velocity process does not give them.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    depth_names = [n for n in baseline.outputs if baseline.payloads.get(n) == "depth"]
    out = Comparison(mode, estimates=(sum(len(result.outputs.get(n, ())) for n in depth_names),
                                      sum(len(baseline.outputs[n]) for n in depth_names)))
    diff = out.differences
    for name in EXACT_FIELDS:
        a, b = getattr(result, name), getattr(baseline, name)
        if a != b:
            diff.append(f"{name}: {a} vs {b}")
    if set(result.outputs) != set(baseline.outputs):
        diff.append(f"outputs: {sorted(result.outputs)} vs {sorted(baseline.outputs)}")
    shifts: dict[str, dict[str, int]] = {}
    slack: dict[str, int] = {}
    unbounded: set[str] = set()
    for name in sorted(set(result.outputs) & set(baseline.outputs)):
        a, b = result.outputs[name], baseline.outputs[name]
        if baseline.payloads.get(name) == "depth":
            process = name.split(".")[0]
            why = None
            if mode == "quantised" and _counts_feeding(network, process, {})[1] is None:
                why = "its process does not read counter spikes, so no quantisation bound is stated for it"
            elif mode == "quantised" and rotation_of(network, process, baseline.outputs, recording) is False:
                why = ("its process compensates rotation (b_w) and the bound needs the angular velocity updates "
                       "(probe the port feeding b_w) and the intrinsics")
            if why is not None:
                out.notes.append(f"{name}: not compared between float and fixed arithmetic: {why}")
                unbounded.add(process)
                continue
            _compare_depth(name, a, b, mode, result, baseline, network, diff, shifts, slack, recording)
        else:
            _compare_records(name, a, b, mode, diff)
    _compare_counts(result.counts, baseline.counts, shifts, diff, unbounded, slack)
    diff += visible_differences(result, baseline, ESTIMATE_KEYS if mode == "quantised" else ())
    return out


#: Rejections decided on the depth or the share, between which quantisation may move an estimate.
VALUE_REASONS = ("too_near", "too_far", "rotation_dominated")


def _compare_counts(ra: dict, rb: dict, shifts: dict, diff: list[str], skip: set[str], slack: dict) -> None:
    if set(ra) != set(rb):
        diff.append(f"counts of processes {sorted(ra)} vs {sorted(rb)}")
        return
    for process in ra:
        if process in skip:
            continue
        a, b = dict(ra[process]), dict(rb[process])
        for reason, delta in shifts.get(process, {}).items():  # boundary estimates explain these
            a[reason] = a.get(reason, 0) + delta
            if reason in VALUE_REASONS:
                a["emitted"] = a.get("emitted", 0) - delta
        if process in slack:
            # Neurons whose share lies within the tolerance of min_share may be rejected for another
            # reason on the other side (rotation_dominated vs too_near/too_far): each moves one count.
            moved = sum(abs(a.get(r, 0) - b.get(r, 0)) for r in VALUE_REASONS)
            if moved <= 2 * slack[process]:
                a.update({r: b.get(r, 0) for r in VALUE_REASONS})
        if a != b:
            explained = f" (boundary estimates explain {shifts[process]})" if process in shifts else ""
            diff.append(f"counts of {process}: {ra[process]} vs {rb[process]}{explained}")


def _compare_records(name: str, a: np.ndarray, b: np.ndarray, mode: str, diff: list[str]) -> None:
    if a.dtype != b.dtype:
        diff.append(f"{name}: record layouts differ ({a.dtype} vs {b.dtype})")
        return
    floats = [f for f in a.dtype.names if a.dtype[f].kind == "f"]
    if mode == "exact" or not floats:
        if a.tobytes() != b.tobytes():
            diff.append(f"{name}: " + _first_row_difference(a, b, ()))
        return
    ints = [f for f in a.dtype.names if f not in floats]
    if len(a) != len(b) or any(not np.array_equal(a[f], b[f]) for f in ints):
        diff.append(f"{name}: " + _first_row_difference(repack_fields(a[ints]), repack_fields(b[ints]), ()))
        return
    for f in floats:
        bad = ~np.isclose(a[f], b[f], rtol=FLOAT_RTOL, atol=0.0, equal_nan=True)
        if bad.any():
            i = int(np.argmax(bad))
            diff.append(f"{name}: {f} at row {i}: {a[f][i]!r} vs {b[f][i]!r} (rtol {FLOAT_RTOL:g})")
            return


def _counts_feeding(network: Network, depth_process: str, outputs: dict):
    """The probed counter spikes feeding a depth process and their largest value (``counter_max``)."""
    process = network.process(depth_process)
    port = process.ports.get("counts")
    source = getattr(port, "source", None)
    if source is None:
        return None, None
    bits = source.process.values.get("counter_bits")
    return outputs.get(source.qualified_name), (None if bits is None else (1 << int(bits)) - 1)


@dataclass
class Rotation:
    """What the eq. 7 bound of one depth process needs: the angular velocity updates it received
    (``step``, ``wx``, ``wy``, ``wz``), the intrinsics of ``B ω`` and its ``min_share``."""

    updates: np.ndarray
    intrinsics: tuple[float, float, float, float]
    min_share: float

    def flow(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``B ω`` (px/s) the depth neurons of ``rows`` (``step``, ``x``, ``y``) held: the latest update
        sent before their step (docs/semantics.md), zero before the first."""
        i = np.searchsorted(self.updates["step"], rows["step"].astype(np.int64) - 1, side="right") - 1
        w = np.zeros((len(rows), 3))
        held = i >= 0
        for k, field in enumerate(("wx", "wy", "wz")):
            w[held, k] = self.updates[field][i[held]]
        return rotational_flow(w[:, 0], w[:, 1], w[:, 2], rows["x"].astype(np.float64), rows["y"].astype(np.float64),
                               *self.intrinsics)


def rotation_of(network: Network, depth_process: str, outputs: dict, recording=None):
    """The ``Rotation`` of a depth process with ``b_w`` connected, None without, False when the
    angular velocity updates (a probe of the port feeding ``b_w``) or the intrinsics are missing."""
    port = network.process(depth_process).ports.get("b_w")
    source = getattr(port, "source", None)
    if source is None:
        return None
    updates = outputs.get(source.qualified_name)
    given = source.process.values.get("intrinsics")
    if given is None and recording is not None and recording.intrinsics is not None:
        k = recording.intrinsics
        given = (k.fx, k.fy, k.cx, k.cy)
    if updates is None or given is None:
        return False
    return Rotation(updates, tuple(float(v) for v in given), float(network.process(depth_process).min_share))


def _compare_depth(name, a, b, mode, result, baseline, network, diff, shifts, slack, recording) -> None:
    for label, d, res in (("result", a, result), ("baseline", b, baseline)):
        if len(d) and np.any((np.diff(d["step"]) == 0) & (np.diff(d["y"]) == 0) & (np.diff(d["x"]) == 0)):
            diff.append(f"{name}: {label}: two estimates for one pixel in one step")
        if not np.array_equal(d["t"], res.t0_us + (d["step"] + 1) * res.timestep_us):
            diff.append(f"{name}: {label}: depth t is not the end of its step")
    if mode == "exact":
        if a.tobytes() != b.tobytes():
            diff.append(f"{name}: " + _first_row_difference(a, b, ("step", "y", "x")))
        return
    only_a, only_b, za, zb, keys = _join(a, b)
    if mode == "float":
        if len(only_a) or len(only_b):
            diff.append(f"{name}: " + _missing(a, only_a, b, only_b))
        bad = np.abs(za - zb) > FLOAT_RTOL * np.maximum(np.abs(za), np.abs(zb))
        if bad.any():
            i = int(np.argmax(bad))
            diff.append(f"depth z at {_where(keys[i])}: {za[i]!r} vs {zb[i]!r} (rtol {FLOAT_RTOL:g})")
        return
    fixed = result if result.extra.get("frac_bits") is not None else baseline
    frac_bits = int(fixed.extra.get("frac_bits", DEFAULT_FRAC_BITS))
    process_name = name.split(".")[0]
    process = network.process(process_name)
    width, height = process.sensor_size
    lo, hi = process.values.get("min_depth", -np.inf), process.values.get("max_depth", np.inf)
    tot, counter_max = _counts_feeding(network, process_name, baseline.outputs)
    rotation = rotation_of(network, process_name, baseline.outputs, recording)
    payload_bits = int(fixed.extra.get("payload_bits", 24))
    spc = result.timestep_us * 1e-6 / _distance_feeding(network, process_name)
    half = 2.0 ** -(frac_bits + 1)

    def tolerance(rows: np.ndarray, z: np.ndarray) -> np.ndarray:
        if tot is None:  # no spikes to read the counts from: the largest counts possible
            return np.full(len(rows), depth_tolerance(counter_max, counter_max, frac_bits))
        sx, sy = signed_counts(tot, rows, width, height)
        if rotation:  # eq. 7 (docs/fixed_point.md): the share of the fixed-point neuron
            _, share_q = shares(rotation, rows, sx, sy, spc, frac_bits, payload_bits)
            return rotation_depth_tolerance(sx, sy, z, share_q, frac_bits) + 1e-12 * np.abs(z)
        return depth_tolerance(sx, sy, frac_bits) + 1e-12 * np.abs(rows["z"])  # + float64 rounding of z

    tol = tolerance(keys, np.maximum(np.abs(za), np.abs(zb)))
    bad = np.abs(za - zb) > tol
    if bad.any():
        i = int(np.argmax(bad))
        diff.append(f"depth z at {_where(keys[i])}: {za[i]!r} vs {zb[i]!r} (tolerance {tol[i]:.3g} m)")
    shift = {"too_near": 0, "too_far": 0, "rotation_dominated": 0}  # result's counts + shift == baseline's
    for rows, sign, side in ((a[only_a], 1, "result"), (b[only_b], -1, "baseline")):
        if not len(rows):
            continue
        # The thresholds are quantised too (round half away), which moves them by up to half an LSB.
        t = tolerance(rows, np.abs(rows["z"])) + half
        near, far = np.abs(rows["z"] - lo) <= t, np.abs(rows["z"] - hi) <= t
        share_edge = np.zeros(len(rows), dtype=bool)
        if rotation:  # kept by one side, rotation_dominated on the other: the share within its error of min_share
            sx, sy = signed_counts(tot, rows, width, height)
            share, _ = shares(rotation, rows, sx, sy, spc, frac_bits, payload_bits)
            share_edge = np.abs(share - rotation.min_share) <= (np.abs(sx) + np.abs(sy)) * half + half
        if not np.all(near | far | share_edge):
            i = int(np.argmax(~(near | far | share_edge)))
            limits = "min/max depth" + (" or of min_share" if rotation else "")
            diff.append(f"depth: {_where(rows[i])} z {rows['z'][i]:.6g} only in the {side}, "
                        f"not within {t[i]:.3g} m of {limits}")
        shift["rotation_dominated"] += sign * int(np.count_nonzero(share_edge))
        shift["too_near"] += sign * int(np.count_nonzero(near & ~share_edge))
        shift["too_far"] += sign * int(np.count_nonzero(far & ~near & ~share_edge))
    if any(shift.values()):
        shifts[process_name] = shift
    if rotation and tot is not None:
        slack[process_name] = _near_min_share(rotation, tot, width, height, spc, frac_bits, payload_bits)


def _distance_feeding(network: Network, depth_process: str) -> int:
    source = getattr(network.process(depth_process).ports.get("counts"), "source", None)
    return int(source.process.values.get("distance", 1)) if source is not None else 1


def shares(rotation: Rotation, rows: np.ndarray, sx: np.ndarray, sy: np.ndarray, spc: float, frac_bits: int,
           payload_bits: int) -> tuple[np.ndarray, np.ndarray]:
    """The translational share of each estimate's neuron: float ``1 − (B ω)·td`` and the fixed-point
    ``r_raw 2**-F`` (``V = quantize(B ω dt / distance)``, docs/fixed_point.md)."""
    bw_x, bw_y = rotation.flow(rows)
    share = 1.0 - (bw_x * sx + bw_y * sy) * spc
    v_x = np.array([quantize(v * spc, frac_bits, payload_bits) for v in bw_x], dtype=np.int64)
    v_y = np.array([quantize(v * spc, frac_bits, payload_bits) for v in bw_y], dtype=np.int64)
    return share, ((1 << frac_bits) - sx * v_x - sy * v_y) * 2.0 ** -frac_bits


def _near_min_share(rotation: Rotation, tot: np.ndarray, width: int, height: int, spc: float, frac_bits: int,
                    payload_bits: int) -> int:
    """Depth neurons reached whose share lies within its quantisation error of ``min_share``."""
    if not len(tot):
        return 0
    key = ((tot["step"].astype(np.int64) + 1) * height + tot["y"]) * width + tot["x"]
    first = np.unique(key, return_index=True)[1]
    neurons = np.zeros(len(first), dtype=[("step", "<i8"), ("x", "<u2"), ("y", "<u2"), ("z", "<f8")])
    neurons["step"], neurons["x"], neurons["y"] = tot["step"][first] + 1, tot["x"][first], tot["y"][first]
    sx, sy = signed_counts(tot, neurons, width, height)
    share, _ = shares(rotation, neurons, sx, sy, spc, frac_bits, payload_bits)
    half = 2.0 ** -(frac_bits + 1)
    return int(np.count_nonzero(np.abs(share - rotation.min_share) <= (np.abs(sx) + np.abs(sy)) * half + half))


def signed_counts(tot: np.ndarray, depth: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """The signed axis counts ``(m_x, m_y)`` behind each estimate, from the spikes one step earlier.

    Both directions fired: the smaller count wins, a tie is 0 (docs/semantics.md).
    """
    key_d = (depth["step"].astype(np.int64) * height + depth["y"]) * width + depth["x"]
    key_t = ((tot["step"].astype(np.int64) + 1) * height + tot["y"]) * width + tot["x"]
    order = np.argsort(key_d, kind="stable")
    idx = np.searchsorted(key_d[order], key_t)
    hit = idx < len(key_d)
    hit[hit] = key_d[order][idx[hit]] == key_t[hit]
    m = np.zeros((4, len(depth)), dtype=np.int64)
    m[tot["direction"][hit].astype(np.int64), order[idx[hit]]] = tot["count"][hit]

    def axis(pos, neg):
        return np.where((pos > 0) & ((neg == 0) | (pos < neg)), pos,
                        np.where((neg > 0) & ((pos == 0) | (neg < pos)), -neg, 0))
    return axis(m[0], m[1]), axis(m[2], m[3])


def _join(a: np.ndarray, b: np.ndarray):
    """Estimates present on both sides (their z and rows) and the indices present on one only."""
    ka = np.stack([a["step"], a["y"].astype(np.int64), a["x"].astype(np.int64)], axis=1)
    kb = np.stack([b["step"], b["y"].astype(np.int64), b["x"].astype(np.int64)], axis=1)
    ua = {tuple(k): i for i, k in enumerate(ka.tolist())}
    ub = {tuple(k): i for i, k in enumerate(kb.tolist())}
    both = [k for k in ua if k in ub]
    ia = np.array([ua[k] for k in both], dtype=np.int64)
    ib = np.array([ub[k] for k in both], dtype=np.int64)
    only_a = np.array(sorted(ua[k] for k in ua if k not in ub), dtype=np.int64)
    only_b = np.array(sorted(ub[k] for k in ub if k not in ua), dtype=np.int64)
    return only_a, only_b, a["z"][ia], b["z"][ib], a[ia]


def _where(row) -> str:
    return f"(step {int(row['step'])}, x {int(row['x'])}, y {int(row['y'])})"


def _missing(a, only_a, b, only_b) -> str:
    first = [(tuple(int(r[k]) for k in ("step", "y", "x")), side, r)
             for rows, side in ((a[only_a], "result"), (b[only_b], "baseline")) for r in rows[:1]]
    key, side, row = min(first, key=lambda f: f[0])
    return (f"{len(only_a)} estimates only in the result, {len(only_b)} only in the baseline; first "
            f"{_where(row)} z {row['z']:.6g} only in the {side}")


def _first_row_difference(a: np.ndarray, b: np.ndarray, key: tuple[str, ...]) -> str:
    """Where two sorted record arrays first differ, as readable text."""
    n = min(len(a), len(b))
    raw = (np.dtype((np.void, a.dtype.itemsize)))
    differ = np.nonzero(a[:n].view(raw) != b[:n].view(raw))[0] if a.dtype == b.dtype else np.arange(n)
    if len(differ):
        i = int(differ[0])
        return f"{len(a)} vs {len(b)} rows; first difference at row {i}: {_row(a[i])} vs {_row(b[i])}"
    extra, side = (a[n], "result") if len(a) > n else (b[n], "baseline")
    return f"{len(a)} vs {len(b)} rows; row {n} only in the {side}: {_row(extra)}"


def _row(row) -> str:
    return "(" + ", ".join(f"{name} {row[name]!r}" if row.dtype[name].kind == "f" else f"{name} {int(row[name])}"
                           for name in row.dtype.names) + ")"
