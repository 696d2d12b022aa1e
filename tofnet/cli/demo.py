"""``tofnet demo``: the main job end to end on a built-in scene — simulate, run, evaluate, plot."""

from __future__ import annotations

import time
from pathlib import Path

from tofnet.errors import TofnetError


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="simulate a scene, estimate depth, score it and draw figures",
                              description="Runs the whole pipeline on a built-in simulated scene "
                                          "(no arguments needed) and tells you where the pictures are.")
    p.add_argument("--out", default="tofnet-demo",
                   help="output folder (default: ./tofnet-demo); the demo replaces its own files there "
                        "(recording/, depth.npz, eval.json, figures/) on every run")
    p.add_argument("--scenario", default="slider", help="built-in scenario (default: slider, the paper's Table 2)")
    p.add_argument("--duration", type=float, default=0.5, help="seconds of camera motion (default: 0.5)")
    p.add_argument("--backend", default=None, help="backend (default: fixed)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.api import DEFAULT_BACKEND, run
    from tofnet.eval.metrics import evaluate
    from tofnet.eval.plots import plot_all
    from tofnet.io import read_recording
    from tofnet.io.depth import write_depth
    from tofnet.sim.run import simulate

    from tofnet.io.files import check_folder_writable, write_text_atomic

    started = time.perf_counter()
    out = Path(args.out)
    # The demo's folder is its own: its files are replaced on every run, without --force
    # (docs/reliability.md). Only a folder that cannot be written is refused up front.
    if out.exists() and not out.is_dir():
        raise TofnetError(f"{out}: --out exists and is not a folder")
    check_folder_writable(out, "--out")
    recording_dir = out / "recording"
    backend = args.backend or DEFAULT_BACKEND
    print(f"[1/4] simulating '{args.scenario}' for {args.duration:g} s -> {recording_dir}")
    sim = simulate(args.scenario, recording_dir, duration=args.duration, seed=args.seed)
    print(f"      {sim['events']:,} events, true depth {sim['depth_min']:.2f}..{sim['depth_max']:.2f} m "
          f"({sim['sim_time_s']:.1f} s)")

    recording = read_recording(recording_dir)
    print(f"[2/4] running the depth network on the '{backend}' backend")
    result, compiled = run(recording, backend=backend)
    depth_path = out / "depth.npz"
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
    write_depth(depth_path, result.depth, **meta, summary=result.summary())
    dropped = sum(result.dropped.values())
    print(f"      {result.events_in:,} events in, {dropped:,} dropped by the input filter, "
          f"{len(result.depth):,} depth estimates -> {depth_path}")
    print(f"      {compiled.cores_used} neuromorphic cores on {compiled.chips_used} chip(s); "
          f"latency {result.latency_steps} steps; network time {result.wall_time:.2f} s")

    print("[3/4] scoring against the ground truth")
    evaluation = evaluate(recording, result.depth, meta)
    print(_indent(evaluation.table()))
    write_text_atomic(out / "eval.json", evaluation.to_json() + "\n")

    print("[4/4] drawing figures")
    paths = plot_all(recording, result.depth, meta, out / "figures")
    for path in paths:
        print(f"      {path}")
    print(f"done in {time.perf_counter() - started:.1f} s. Open the PNGs in {out / 'figures'} to see the depth maps.")
    return 0


def _indent(text: str) -> str:
    return "\n".join("      " + line for line in text.splitlines())
