"""Depth accuracy of the paper's network on every built-in simulated scenario (run by hand, not in CI).

    python benchmarks/accuracy.py                      # 1 s per scenario, seed 0, 240x180
    python benchmarks/accuracy.py --scenarios slider,all_axes --duration 0.5
    python benchmarks/accuracy.py --scenarios slider,wobble_slider,tracking_slider,pan   # the turning camera

Each scenario is simulated (``tofnet.sim``; cached under ``--cache``, by default a
folder in the system's temp dir, keyed by the scenario's full config, the seed and the
simulator's source), run through the paper's network at 1 ms steps with 8-bit
counters and the default refractory period (``tofnet.processes.input.DEFAULT_REFRACTORY``),
and scored against the per-event ground truth with ``tofnet.eval.metrics.evaluate``.
A scenario whose camera turns (``ROTATION_SCENARIOS``) gets three rows: the paper's
network (eq. 8, rotation not compensated), and eq. 7 with ``ω`` from the poses
(``groundtruth.txt``, 1 kHz, as ``tofnet run`` reads them) and from the gyroscope
(``imu.txt``); their verdict is the issue's bar for a camera whose translation dominates
(median |rel| within 1.5x of ``slider``'s at the same pixels, median signed error within
±5 %), and the error of the eq. 7 rows is then split by the true translational share
(``tofnet.eval.rotation.split_by_true_share``: the e / r law). Beside each of the paper
network's rows, the time-surface estimator's (beyond the paper: ``improved_network``, its
defaults, docs/time_surface.md) on the same events, with the issue's bars: on slider and
all_axes a median at most half the paper network's, coverage >= 10 % and a bias within
±3 %; elsewhere a median not above the paper network's row (on a turning camera both
compensate the rotation: eq. 7 with ω from the poses). Every row also has its coverage by
true-depth band and by motion phase (``tofnet.eval.breakdown``, as ``tofnet eval`` prints it;
``benchmarks/motion_sweep.py`` has the random scenes under general motion). The table
goes to stdout twice: as text and as markdown (for docs/accuracy.md and the README),
followed by the command that reproduces it. Progress goes to stderr.

The helpers here (``recording_for``, ``run_network``, ``attribution`` ...) are shared
by ``refractory_sweep.py`` and ``accuracy_decomposition.py``; see docs/accuracy.md.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import tofnet
from tofnet.api import run
from tofnet.eval.breakdown import PHASES, breakdown_columns
from tofnet.eval.metrics import Evaluation, evaluate
from tofnet.eval.rotation import split_by_true_share
from tofnet.io.recording import Recording
from tofnet.networks import depth_network, improved_network
from tofnet.processes.input import DEFAULT_REFRACTORY
from tofnet.sim import SCENARIOS, SimConfig, generate, scenario
from tofnet.sim.scenarios import ESIM_EXAMPLE_PIXELS, ROOM_SCENARIOS, ROTATION_SCENARIOS

#: Every built-in scenario: the desk scenes (0.35-3 m), the room scenes at the paper's depths, the turning camera.
ALL_SCENARIOS = list(SCENARIOS) + list(ROOM_SCENARIOS) + list(ROTATION_SCENARIOS)
#: Turning-camera scenarios whose translation dominates: the issue's bar applies to their eq. 7 rows.
TRANSLATION_DOMINATES = ("tracking_slider",)
#: Mixed motion (a shaky hand: the image moves along both axes, true share 0.5-1.5): the ratio
#: to slider is shown, not judged (docs/rotation.md, "Why the wobble stays harder").
MIXED_MOTION = ("wobble_slider",)
#: The issue's bar: eq. 7's median |rel| at most this times slider's, and |median signed error| at most BAR_BIAS %.
BAR_RATIO, BAR_BIAS = 1.5, 5.0
#: The time-surface estimator's bars (issue 13): on these scenarios a median at most IMPROVED_RATIO times the paper
#: network's, coverage >= IMPROVED_COVERAGE % and |bias| <= IMPROVED_BIAS %; elsewhere a median not above it.
IMPROVED_SCENARIOS, IMPROVED_RATIO, IMPROVED_COVERAGE, IMPROVED_BIAS = ("slider", "all_axes"), 0.5, 10.0, 3.0

#: The paper's synthetic results (§5.1): scenario -> (table, mean abs m, mean rel %, median abs m, median rel %).
TABLE_2 = ("Table 2", 0.810, 13.279, 0.345, 5.598)
TABLE_1 = ("Table 1", 1.670, 31.937, 0.854, 16.926)
PAPER = {"slider": TABLE_2, "all_axes": TABLE_1, "room_slider": TABLE_2, "room_all_axes": TABLE_1,
         "paper_slider": TABLE_2, "paper_all_axes": TABLE_1}

#: One line per scenario for the "why" column (the measurements behind them are in docs/accuracy.md).
WHY = {
    "slider": "threshold mismatch x 2-px edges: first events jitter ~0.2 px (paper_slider has neither)",
    "fast_slider": "2.6 m/s, ~4 steps/px: discretisation, and the refractory drops edges (5-10 ms suits it)",
    "vertical": "as slider, at 0.4 m/s",
    "diagonal": "as slider; both axes measured, each with its own timing error",
    "all_axes": "as slider, plus the z segment (slow flow near the focus of expansion) and turns",
    "forward": "pure z motion: flow ~0 near the focus of expansion (paper 5.1)",
    "room_slider": "as slider; beyond ~6 m an edge takes longer than 60 ms per px (bias)",
    "room_all_axes": "as room_slider; at 0.4 m/s and 6-10 m, 90-125 ms per px (bias), z segment",
    "paper_slider": "paper's depths with ESIM's example pixels: no mismatch, C 0.5, sharp edges",
    "paper_all_axes": "as paper_slider, plus the z segment and turns",
    "wobble_slider": "a hand's wobble (~1 deg, 1-4 Hz) on the slider: eq. 8 reads the turn as depth",
    "tracking_slider": "turning to keep the scene centred (r 1.1-2.3): eq. 8 overestimates",
    "pan": "a pan on a slow slide (r < 0.75): rotation dominates, error ~ e / r",
}

#: A change to the simulator (or the lens maths it casts distorted rays with) invalidates the cache.
SIM_SOURCES = sorted((Path(tofnet.__file__).parent / "sim").glob("*.py")) + [
    Path(tofnet.__file__).parent / "kernels" / "undistort.py"]


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def default_backend() -> str:
    """``fixed`` when registered (fast, event-driven), else ``reference``."""
    from tofnet.backends.registry import available_backends
    return "fixed" if "fixed" in available_backends() else "reference"


def default_cache() -> Path:
    return Path(os.environ.get("TOFNET_ACCURACY_CACHE", Path(tempfile.gettempdir()) / "tofnet-accuracy"))


def _key(config: SimConfig, seed: int) -> str:
    h = hashlib.sha256()
    h.update(repr(config).encode())
    h.update(str(seed).encode())
    for path in SIM_SOURCES:  # a change to the simulator invalidates the cache
        h.update(path.read_bytes())
    return h.hexdigest()[:20]


def recording_for(config: SimConfig, seed: int = 0, cache: Path | None = None, quiet: bool = False) -> Recording:
    """The simulated recording of ``config`` (events, ground-truth depth, exact trajectory), cached as ``.npz``."""
    path = None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        path = cache / f"{config.name}-{_key(config, seed)}.npz"
        if path.exists():
            data = np.load(path)
            return Recording(events=data["events"], intrinsics=config.intrinsics, trajectory=config.trajectory,
                             sensor_size=config.sensor_size, gt_depth=data["gt_depth"].astype(np.float64),
                             source=f"sim:{config.name}:seed={seed}")
    start = time.perf_counter()
    result = generate(config, seed=seed)
    if not quiet:
        log(f"  simulated {config.name}: {len(result.events):,} events in {time.perf_counter() - start:.1f} s")
    if path is not None:
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, events=result.events, gt_depth=result.gt_depth)
        tmp.replace(path)
    return result.to_recording()


def scenario_config(name: str, duration: float = 1.0, size: tuple[int, int] = (240, 180), **changes) -> SimConfig:
    """A built-in scenario at ``size`` with ``SimConfig`` fields changed (e.g. ``contrast_sigma=0``)."""
    config = scenario(name, duration)
    if tuple(size) != tuple(config.sensor_size):
        config = config.replace(sensor_size=tuple(size))
    return config.replace(**changes) if changes else config


@dataclass
class Run:
    """One network run on one recording and its evaluation."""

    recording: Recording
    result: object  # tofnet.backends.base.RunResult
    evaluation: Evaluation
    params: dict

    def metrics(self) -> dict:
        e = self.evaluation
        return {"events": e.events_in, "accepted": self.result.accepted, "estimates": e.estimates,
                "matched": e.matched, "coverage_pct": 100 * e.coverage, "mean_abs_m": e.errors.mean_abs_m,
                "median_abs_m": e.errors.median_abs_m, "mean_rel_pct": e.errors.mean_rel_pct,
                "median_rel_pct": e.errors.median_rel_pct, "bias_pct": e.errors.bias_rel_pct,
                "wall_s": self.result.wall_time,
                **breakdown_columns(self.result.depth, e.matches, self.recording)}


def run_network(recording: Recording, *, backend: str | None = None, refractory: str | None = None,
                distance: int = 1, counter_bits: int = 8, timestep: str = "1ms", velocity_per: str = "patch",
                per_polarity: bool = False, rotation: str | None = None) -> Run:
    """The paper's network (defaults: 1 ms steps, 8-bit counters, per-patch ``A t``) on ``recording``.

    ``rotation``: the angular velocity source (``"groundtruth"``, ``"gyro"``) of eq. 7; None: eq. 8.
    """
    params = {"timestep": timestep, "refractory_per_polarity": per_polarity}
    if refractory is not None:
        params["refractory"] = refractory
    net = depth_network(recording.sensor_size, input=params, time_of_travel={"distance": distance,
                                                                             "counter_bits": counter_bits},
                        velocity={"per": velocity_per},
                        rotation=None if rotation is None else {"source": rotation})
    result, _ = run(recording, net, backend=backend or default_backend())
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
    evaluation = evaluate(recording, result.depth, meta, window_s=0)
    return Run(recording, result, evaluation, dict(params, distance=distance, counter_bits=counter_bits,
                                                   velocity_per=velocity_per, backend=backend or default_backend(),
                                                   rotation=rotation))


def run_improved(recording: Recording, *, backend: str | None = None, rotation: str | None = None,
                 **time_surface) -> Run:
    """The time-surface estimator (``improved_network``: its defaults, ``A t`` per pixel) on ``recording``.

    ``rotation``: the angular velocity source of eq. 7 (as ``run_network``); ``time_surface``
    changes its parameters.
    """
    net = improved_network(recording.sensor_size, time_surface=time_surface,
                           rotation=None if rotation is None else {"source": rotation})
    result, _ = run(recording, net, backend=backend or default_backend())
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
    evaluation = evaluate(recording, result.depth, meta, window_s=0)
    return Run(recording, result, evaluation, dict(time_surface, estimator="improved", rotation=rotation,
                                                   backend=backend or default_backend()))


def improved_verdict(name: str, m: dict, paper: dict) -> tuple[str, str]:
    """The time-surface row's bar (the "paper" column) and verdict, against the paper network's row ``paper``."""
    ratio = m["median_rel_pct"] / paper["median_rel_pct"]
    if name in IMPROVED_SCENARIOS:
        ok = ratio <= IMPROVED_RATIO and m["coverage_pct"] >= IMPROVED_COVERAGE and abs(m["bias_pct"]) <= IMPROVED_BIAS
        return (f"<= {IMPROVED_RATIO * paper['median_rel_pct']:.1f} (half the network's), coverage >= "
                f"{IMPROVED_COVERAGE:g}, bias within ±{IMPROVED_BIAS:g}", f"{'PASS' if ok else 'FAIL'} ({ratio:.2f}x)")
    return f"<= {paper['median_rel_pct']:.1f} (the network's)", f"{'PASS' if ratio <= 1.0 else 'FAIL'} ({ratio:.2f}x)"


def row_of(label: str, m: dict, a: dict, paper: str, verdict: str, why: str) -> list[str]:
    """One row of the accuracy table."""
    return [label, fmt(m["events"]), fmt(m["estimates"]), fmt(m["coverage_pct"]), fmt(m["mean_abs_m"], 3),
            fmt(m["median_abs_m"], 3), fmt(m["mean_rel_pct"]), fmt(m["median_rel_pct"]), f"{m['bias_pct']:+.1f}",
            fmt(float(np.median(a["n"]))), _groups(m, BAND_KEYS), _groups(m, PHASES), paper, verdict, why]


BAND_KEYS = ("lt1m", "1to2m", "2to4m", "4to8m", "ge8m")


def _groups(m: dict, keys) -> str:
    """Coverage % per group as ``a / b / ...`` (``-`` for a group without events)."""
    return " / ".join(fmt(m[f"coverage_{k}_pct"]) for k in keys)


def as_written(recording: Recording, config: SimConfig, seed: int) -> Recording:
    """A simulated recording as ``tofnet run`` reads its folder: poses at ``config.pose_rate`` (slerped)
    instead of the exact motion, and the simulated ``imu.txt``."""
    from tofnet.io.groundtruth import Trajectory
    from tofnet.sim.rotation import imu_samples

    traj = config.trajectory
    times = np.arange(int(np.floor(config.duration * config.pose_rate + 1e-9)) + 1) / config.pose_rate
    poses = Trajectory(times, traj.position_at(times), traj.quaternion_at(times))
    return Recording(recording.events, intrinsics=recording.intrinsics, trajectory=poses,
                     sensor_size=recording.sensor_size, gt_depth=recording.gt_depth,
                     imu=imu_samples(config, seed), source=recording.source)


# --- attribution: where the error comes from -----------------------------------------------------------------


def attribution(r: Run) -> dict[str, np.ndarray]:
    """Per matched estimate: estimate ``z``, truth ``gt``, signed relative error ``rel`` (fraction),
    steps per pixel ``n`` (time the image takes to move one pixel along the flow, in steps, from the
    true depth and the exact per-pixel ``A t``), time ``t`` (s since t0), segment index ``seg``."""
    e, res, rec = r.evaluation, r.result, r.recording
    m = e.matches
    valid = m.valid
    depth = res.depth[valid]
    gt = m.gt[valid]
    t = (m.input_step[valid] + 0.5) * res.timestep_us * 1e-6  # s since t0
    t_abs = t + res.t0_us * 1e-6
    vel = rec.trajectory.velocity_at(t_abs)
    k = rec.intrinsics
    at_x = -k.fx * vel[:, 0] + (depth["x"] - k.cx) * vel[:, 2]
    at_y = -k.fy * vel[:, 1] + (depth["y"] - k.cy) * vel[:, 2]
    speed = np.hypot(at_x, at_y)  # px*m/s
    with np.errstate(divide="ignore"):
        n = gt / speed / (res.timestep_us * 1e-6)
    seg = rec.trajectory.segment_index(t_abs) if hasattr(rec.trajectory, "segment_index") else np.zeros(len(t), int)
    return {"z": depth["z"].astype(np.float64), "gt": gt, "rel": (depth["z"] - gt) / gt, "n": n, "t": t,
            "seg": seg, "x": depth["x"], "y": depth["y"]}


def discretisation_floor(n: np.ndarray, distance: int = 1, seed: int = 0) -> np.ndarray:
    """Relative error each estimate would have from the timestep alone.

    An edge that takes ``distance * n`` steps (non-integer) between the facilitating
    and the trigger pixel, at a uniformly random phase within the step, is counted
    as ``floor(phase + distance * n)`` steps (docs/semantics.md): the error of a
    perfect camera and a perfect pairing.
    """
    rng = np.random.default_rng(seed)
    span = distance * np.asarray(n, dtype=np.float64)
    phase = rng.uniform(0, 1, size=span.shape)
    m = np.floor(phase + span)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(m / span - 1)


def binned(values: np.ndarray, rel: np.ndarray, edges: list[float], floor: np.ndarray | None = None) -> list[dict]:
    """Per bin of ``values``: share of estimates, median |rel| %, bias %, and the discretisation floor %."""
    out = []
    total = len(values)
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (values >= lo) & (values < hi)
        k = int(sel.sum())
        row = {"lo": lo, "hi": hi, "share_pct": 100 * k / total if total else math.nan}
        row["median_rel_pct"] = 100 * float(np.median(np.abs(rel[sel]))) if k else math.nan
        row["bias_pct"] = 100 * float(np.median(rel[sel])) if k else math.nan
        if floor is not None:
            row["floor_pct"] = 100 * float(np.median(floor[sel])) if k else math.nan
        out.append(row)
    return out


# --- tables ---------------------------------------------------------------------------------------------------


def fmt(value, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if isinstance(value, (int, np.integer)):
        return f"{value:,}"
    if isinstance(value, (float, np.floating)):
        return f"{value:.{digits}f}"
    return str(value)


def text_table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)]
    lines = ["  ".join(h.rjust(w) if i else h.ljust(w) for i, (h, w) in enumerate(zip(header, widths)))]
    lines.append("  ".join("-" * w for w in widths))
    for r in rows:
        lines.append("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths))))
    return "\n".join(lines)


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" if i == 0 else "---:" for i in range(len(header)))
             + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def print_tables(header: list[str], rows: list[list[str]], title: str | None = None, blank_after: bool = True) -> None:
    """Print ``title`` (if given) and a blank line, the table as text, a blank line, the table as markdown and,
    if ``blank_after``, a blank line: how the benchmarks print their tables."""
    if title is not None:
        print(title + "\n")
    print(text_table(header, rows) + "\n")
    print(markdown_table(header, rows) + ("\n" if blank_after else ""))


def reproduce(script: str, options: list[tuple]) -> str:
    """``reproduce: python benchmarks/<script>`` and ``flag value`` for each ``(flag, value, default[, format
    spec])`` of ``options`` whose value is not its default: the line that ends a benchmark's output."""
    return " ".join([f"reproduce: python benchmarks/{script}"]
                    + [f"{flag} {format(value, *spec)}" for flag, value, default, *spec in options if value != default])


def parse_size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default=",".join(ALL_SCENARIOS), help="comma-separated (default: all built-in)")
    parser.add_argument("--duration", type=float, default=1.0, help="seconds per scenario (default 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", default="240x180", help="sensor WxH (default 240x180)")
    parser.add_argument("--backend", default=None, help="default: fixed if registered, else reference")
    parser.add_argument("--refractory", default=None, help=f"default: the network's ({DEFAULT_REFRACTORY})")
    parser.add_argument("--pixels", choices=("default", "esim"), default="default",
                        help="esim: every scenario with ESIM's example pixels (C 0.5, no threshold mismatch)")
    parser.add_argument("--cache", default=str(default_cache()), help="simulation cache folder ('' = none)")
    args = parser.parse_args(argv)
    names = [s for s in args.scenarios.split(",") if s]
    size = parse_size(args.size)
    backend = args.backend or default_backend()
    cache = Path(args.cache) if args.cache else None
    refractory = args.refractory or DEFAULT_REFRACTORY
    log(f"accuracy: {len(names)} scenarios, {args.duration:g} s, seed {args.seed}, {size[0]}x{size[1]}, "
        f"backend {backend}, refractory {refractory}, 1 ms steps, 8-bit counters")

    header = ["scenario", "events", "estimates", "coverage %", "mean abs m", "median abs m", "mean rel %",
              "median rel %", "bias %", "steps/px",
              "coverage % by depth (<1 / 1-2 / 2-4 / 4-8 / >=8 m)", "coverage % steady / reversal", "bar: median rel % (paper, or issue)", "verdict", "why"]
    rows, splits, slider = [], [], None
    for name in names:
        log(f"{name}:")
        config = scenario_config(name, args.duration, size, **(ESIM_EXAMPLE_PIXELS if args.pixels == "esim" else {}))
        rec = recording_for(config, args.seed, cache)
        turning = name in ROTATION_SCENARIOS
        if turning:
            rec = as_written(rec, config, args.seed)
        variants = [(None, name)] + ([("groundtruth", f"{name}, eq. 7 (poses)"), ("gyro", f"{name}, eq. 7 (gyro)")]
                                     if turning else [])
        paper_rows = {}
        for rotation, label in variants:
            start = time.perf_counter()
            r = run_network(rec, backend=backend, refractory=refractory, rotation=rotation)
            m = r.metrics()
            paper_rows[rotation] = m
            a = attribution(r)
            log(f"  {label}: ran and scored in {time.perf_counter() - start:.1f} s: median rel "
                f"{m['median_rel_pct']:.1f} %, bias {m['bias_pct']:+.1f} %")
            target = PAPER.get(name)
            if name == "slider":
                slider = m["median_rel_pct"]
            if rotation is not None and name in TRANSLATION_DOMINATES and slider is not None:
                ratio = m["median_rel_pct"] / slider
                paper = f"<= {BAR_RATIO:g}x slider, bias within ±{BAR_BIAS:g}"
                verdict = (f"{'PASS' if ratio <= BAR_RATIO and abs(m['bias_pct']) <= BAR_BIAS else 'FAIL'} "
                           f"({ratio:.2f}x)")
            elif rotation is not None and name in MIXED_MOTION and slider is not None:
                paper, verdict = "- (mixed motion)", f"{m['median_rel_pct'] / slider:.2f}x slider"
            elif target is None:
                paper, verdict = "-", "-"
            else:
                paper = f"<= {target[4]:.1f} ({target[0]})"
                verdict = "PASS" if m["median_rel_pct"] <= target[4] else "FAIL"
            why = WHY.get(name, "") if rotation is None else \
                f"rotation compensated, ω from the {'poses' if rotation == 'groundtruth' else 'gyroscope'}"
            rows.append(row_of(label, m, a, paper, verdict, why))
            if turning and rotation != "gyro":  # (the simulated gyroscope is noise-free: as the poses)
                splits.append((label, split_by_true_share(rec, r.result.depth, r.evaluation)[0],
                               r.result.rejected["rotation_dominated"]))
        for rotation, label in variants[1:2] if turning else variants:  # the time surface; turning: eq. 7 (poses)
            start = time.perf_counter()
            r = run_improved(rec, backend=backend, rotation=rotation)
            m = r.metrics()
            paper, verdict = improved_verdict(name, m, paper_rows[rotation])
            log(f"  {label}, time surface: ran and scored in {time.perf_counter() - start:.1f} s: median rel "
                f"{m['median_rel_pct']:.1f} %, bias {m['bias_pct']:+.1f} %, coverage {m['coverage_pct']:.1f} %")
            rows.append(row_of(f"{label}, time surface", m, attribution(r), paper, verdict,
                               "the local slope of the time surface (docs/time_surface.md)"))
            if rotation is not None:
                splits.append((f"{label}, time surface", split_by_true_share(rec, r.result.depth, r.evaluation)[0],
                               r.result.counts["time_surface"]["rotation_dominated"]))

    print(f"Depth accuracy, {args.duration:g} s per scenario, seed {args.seed}, {size[0]}x{size[1]}, 1 ms steps, "
          f"8-bit counters, refractory {refractory}, backend {backend}, {args.pixels} pixels")
    print("steps/px: median over estimates of the steps the image takes to move one pixel (true depth, exact A t)")
    print()
    print(text_table(header[:-1], [r[:-1] for r in rows]))
    print()
    print(markdown_table(header, rows))
    print()
    if splits:
        print("Error by the true translational share r (along the true image motion; tofnet eval prints the same):")
        print("e / r law: |rel|*r about flat across bins while |rel| grows as r falls; eq. 8's bias is r - 1")
        split_rows = []
        for label, split, dominated in splits:
            for row in split:
                if row["n"]:
                    split_rows.append([label, f"{row['lo']:g} .. {row['hi']:g}", fmt(row["n"]), f"{row['share']:.2f}",
                                       fmt(100 * row["median_rel"]), f"{100 * row['bias']:+.1f}",
                                       fmt(100 * row["rel_times_share"])])
            split_rows.append([label, "rejected rotation_dominated", fmt(dominated), "", "", "", ""])
        header_split = ["run", "true r", "estimates", "median r", "median |rel| %", "bias %", "|rel|*r %"]
        print_tables(header_split, split_rows)
    print(reproduce("accuracy.py", [("--scenarios", args.scenarios, ",".join(ALL_SCENARIOS)),
                                    ("--duration", args.duration, 1.0), ("--seed", args.seed, 0),
                                    ("--size", args.size, "240x180"), ("--refractory", args.refractory, None),
                                    ("--pixels", args.pixels, "default"), ("--backend", args.backend or None, None)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
