"""``tofnet demo``: the main job end to end on a built-in scene — simulate, run, evaluate, plot.

The paper's network and the time-surface estimator (beyond the paper, docs/time_surface.md)
run on the same events; the figures show the paper's network, and ``compare.png`` both side
by side with their errors.
"""

from __future__ import annotations

import time
from pathlib import Path

from tofnet.units import format_steps


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="simulate a scene, estimate depth, score it and draw figures",
                              description="Runs the whole pipeline on a built-in simulated scene "
                                          "(no arguments needed) and tells you where the pictures are: the "
                                          "paper's network, and beside it the time-surface estimator.")
    p.add_argument("-o", "--out", default="tofnet-demo",
                   help="output folder (default: ./tofnet-demo): new or empty, or an earlier demo's, which is "
                        "replaced as a whole once the new demo is done")
    p.add_argument("--force", action="store_true",
                   help="replace a folder another tofnet command wrote (never one holding files tofnet did not "
                        "write)")
    p.add_argument("--scenario", default="slider", help="built-in scenario (default: slider, the paper's Table 2)")
    p.add_argument("--duration", type=float, default=0.5, help="seconds of camera motion (default: 0.5)")
    p.add_argument("--backend", default=None, help="backend (default: fixed)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(handler=handle)


#: The estimators the demo runs: label, ``tofnet.api.ESTIMATORS`` name, depth file.
ESTIMATORS = (("Paper's network", "paper", "depth.npz"), ("Time-surface estimator", "improved", "depth_improved.npz"))


#: What the demo's manifest says wrote its folder.
DEMO = "tofnet demo"


def handle(args) -> int:
    from tofnet.io.files import atomic_path, check_output
    from tofnet.io.guard import read_manifest
    from tofnet.kernels.compilation import Stopwatch

    clock = Stopwatch()
    # The demo's folder is tofnet's (a manifest lists what it wrote): a folder of other files is refused;
    # an earlier demo's own folder is replaced without --force, so that rerunning the demo just works
    # (docs/reliability.md).
    out = Path(args.out)
    earlier = read_manifest(out) if out.is_dir() and not out.is_symlink() else None
    own = earlier is not None and earlier.get("written_by") == DEMO
    out = check_output(out, force=args.force or own, what="--out", folder=True)
    with atomic_path(out, folder=True, written_by=DEMO) as work:  # put in place once all is written
        _demo(args, out, work)
    print(f"done in {time.perf_counter() - clock.started:.1f} s{_compiled(clock)}. Open the PNGs in "
          f"{out / 'figures'} to see the depth maps (compare.png: both estimators side by side).")
    return 0


def _demo(args, out: Path, work: Path) -> None:
    """The demo, written into ``work`` (a temporary folder); the lines name the files under ``out``."""
    from tofnet.api import DEFAULT_BACKEND, run
    from tofnet.eval.metrics import evaluate
    from tofnet.eval.plots import comparison_figure, plot_all, save_figure
    from tofnet.io import read_recording
    from tofnet.io.depth import write_depth
    from tofnet.io.files import write_text_atomic
    from tofnet.sim.run import simulate

    backend = args.backend or DEFAULT_BACKEND
    print(f"[1/4] simulating '{args.scenario}' for {args.duration:g} s -> {out / 'recording'}")
    sim = simulate(args.scenario, work / "recording", duration=args.duration, seed=args.seed)
    print(f"      {sim['events']:,} events, true depth {sim['depth_min']:.2f}..{sim['depth_max']:.2f} m "
          f"({sim['sim_time_s']:.1f} s)")

    recording = read_recording(work / "recording")
    recording.source = str(out / "recording")  # where it will be: the eval files name it
    print(f"[2/4] running the paper's network and the time-surface estimator on the '{backend}' backend")
    runs = {}
    for label, estimator, name in ESTIMATORS:
        result, compiled = run(recording, backend=backend, estimator=estimator)
        meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
        write_depth(work / name, result.depth, **meta, summary=result.summary())
        runs[label] = (result.depth, meta)
        where = (f"{compiled.cores_used} neuromorphic cores on {compiled.chips_used} chip(s)" if compiled.cores_used
                 else "off-chip (host)")
        print(f"      {label}: {result.events_in:,} events in, {len(result.depth):,} depth estimates -> "
              f"{out / name}; {where}; latency {format_steps(result.latency_steps)}; network time {result.wall_time:.2f} s")

    print("[3/4] scoring against the ground truth")
    for (label, (depth, meta)), (_, _, name) in zip(runs.items(), ESTIMATORS):
        evaluation = evaluate(recording, depth, meta)
        print(f"      {label}:")
        print(_indent(evaluation.table(), 8))
        write_text_atomic(work / name.replace("depth", "eval").replace(".npz", ".json"), evaluation.to_json() + "\n")

    print("[4/4] drawing figures")
    depth, meta = runs[ESTIMATORS[0][0]]
    paths = plot_all(recording, depth, meta, work / "figures")
    paths.append(save_figure(comparison_figure(recording, runs), work / "figures" / "compare.png"))
    for path in paths:
        print(f"      {out / Path(path).relative_to(work)}")


def _compiled(clock) -> str:
    return (f" ({clock.compile_seconds:.0f} s of it compiling kernels: first run only)" if clock.compiled > 0
            else "")


def _indent(text: str, width: int = 6) -> str:
    return "\n".join(" " * width + line for line in text.splitlines())
