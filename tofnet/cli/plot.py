"""``tofnet plot``: figures of depth estimates (depth map, histogram, error over time, 3D cloud)."""

from __future__ import annotations

import sys
from pathlib import Path

from tofnet.cli.eval import add_timing_options, load_inputs
from tofnet.errors import DataError, TofnetError

KIND_HELP = {
    "depthmap": "depth per pixel accumulated over a window, beside the ground truth (paper Fig. 5, 6)",
    "histogram": "histogram of the estimated depths over that of the ground truth, binned on the "
                 "counter's steps when the depths are whole steps (Fig. 4)",
    "error": "camera trajectory and windowed relative error over time (Fig. 3)",
    "cloud": "estimates back-projected to 3D (median per ray where they agree) and seen from above, "
             "with the camera path (Fig. 1)",
    "all": "every figure the recording supports",
    "units": "the four time-of-travel units of chosen pixels at work: counters, spikes, depth (Fig. 2); "
             "runs the network, so DEPTH is not needed",
}


def register(subparsers) -> None:
    kinds = "; ".join(f"{k}: {v}" for k, v in KIND_HELP.items())
    p = subparsers.add_parser("plot", help="figures of depth estimates (PNG)",
                              description=f"Draw depth estimates as PNG figures. Kinds - {kinds}.")
    p.add_argument("kind", choices=tuple(KIND_HELP), help="which figure")
    p.add_argument("recording", help="the recording the depth was computed from (ECD folder or events file)")
    p.add_argument("depth", nargs="?", help="depth estimates written by `tofnet run` (.npz); not for 'units'")
    p.add_argument("-o", "--out", help="PNG to write (a folder for 'all'); default: next to DEPTH, "
                                       "named <depth>_<kind>.png")
    p.add_argument("--window", metavar="START:END|LENGTH",
                   help="time span, seconds since the run's first step (a run on a time window: its start, not "
                        "the recording's first event): '1.2:1.27', '1200ms:1270ms', or a length "
                        "centred in the run, '70ms' (default: 70ms for depthmap, the whole run otherwise)")
    p.add_argument("--error-window", default=None,
                   help="window of the error-over-time figure's band, e.g. '20ms' (default auto: about 200 "
                        "matched estimates per window, at most 100 windows, a round number of timesteps)")
    p.add_argument("--reduce", choices=("latest", "median"), default=None,
                   help="depth map: each pixel's latest or median depth in the window (default latest)")
    p.add_argument("--no-gt", action="store_true", help="leave out the ground truth panels and overlays")
    g = p.add_argument_group("units")
    g.add_argument("--pixel", action="append", default=[], metavar="X,Y",
                   help="a pixel whose units to draw; repeatable (default: the busiest pixel of the window)")
    g.add_argument("--spec", help="YAML network spec (default: the paper's network)")
    from tofnet.cli.trust import add_allow_import
    add_allow_import(g)
    g.add_argument("--backend", default=None, help="backend that runs it (default fixed)")
    g.add_argument("--velocity", metavar="TX,TY,TZ", help="constant camera velocity in m/s instead of the poses")
    p.add_argument("--force", action="store_true", help="overwrite existing PNG files")
    from tofnet.cli.inputs import add_allow_external, add_camera_options, add_sequence_options
    add_allow_external(p)
    add_camera_options(p)
    add_sequence_options(p)
    add_timing_options(p)
    p.set_defaults(handler=handle)


#: Options only one side reads: the units figure runs a network; the others draw a depth file.
_UNITS_ONLY = {"pixel": "--pixel", "spec": "--spec", "allow_import": "--allow-import", "backend": "--backend",
               "velocity": "--velocity"}
_DEPTH_ONLY = {"depth": "DEPTH", "error_window": "--error-window", "reduce": "--reduce", "no_gt": "--no-gt",
               "timestep": "--timestep", "latency_steps": "--latency-steps"}


def _refuse_unused(args) -> None:
    """One line for options the chosen figure would not read (they would be silently ignored)."""
    units = args.kind == "units"
    unused = [flag for name, flag in (_DEPTH_ONLY if units else _UNITS_ONLY).items()
              if getattr(args, name) not in (None, False, [])]
    if unused:
        what = ("runs the network itself (no depth file)" if units
                else "draws a depth file (the units figure runs a network)")
        raise TofnetError(f"plot {args.kind}: {', '.join(unused)} not used: this figure {what}")


def handle(args) -> int:
    _refuse_unused(args)
    if args.kind == "units":
        return handle_units(args)
    if args.depth is None:
        raise TofnetError(f"plot {args.kind}: give the depth file written by `tofnet run` after the recording")
    from tofnet.cli.inputs import camera_options, sequence_options
    from tofnet.eval.metrics import require_timing
    from tofnet.eval.plots import available_kinds, figure, save_figure
    from tofnet.io.ecd import recording_files
    from tofnet.io.files import check_output
    from tofnet.units import seconds

    window_s = None if args.error_window in (None, "auto") else seconds(args.error_window, "--error-window")
    if window_s is not None and window_s <= 0:
        raise TofnetError(f"--error-window must be positive or 'auto', got {args.error_window!r}")
    recording, depth, meta = load_inputs(args.recording, args.depth, timestep=args.timestep,
                                         latency_steps=args.latency_steps, allow_external=args.allow_external,
                                         **sequence_options(args), **camera_options(args))
    require_timing(meta)
    recording = _with_run_camera(recording, meta, args.depth)
    options = {"window": args.window, "window_s": window_s, "reduce": args.reduce or "latest", "with_gt": not args.no_gt}
    depth_path = Path(args.depth)
    support = available_kinds(recording)
    if args.kind == "all":
        folder = Path(args.out) if args.out else depth_path.parent
        prefix = "" if args.out else f"{depth_path.stem}_"
        targets = [(kind, folder / f"{prefix}{kind}.png") for kind in support]
    else:
        reason = support[args.kind]
        if reason is not None:
            raise DataError(f"{recording.source}: the {args.kind} figure {reason}")
        out = Path(args.out) if args.out else depth_path.with_name(f"{depth_path.stem}_{args.kind}.png")
        if out.suffix.lower() != ".png":
            raise TofnetError(f"--out: figures are written as PNG, got {out.name!r}")
        targets = [(args.kind, out)]
    inputs = [*recording_files(args.recording), depth_path]
    for kind, path in targets:
        if support[kind] is None:
            check_output(path, force=args.force, inputs=inputs, what=f"the {kind} figure")
    for kind, path in targets:
        if support[kind] is not None:
            print(f"skipped {kind}: it {support[kind]}", file=sys.stderr)
            continue
        print(save_figure(figure(kind, recording, depth, meta, **options), path))
    return 0


def _with_run_camera(recording, meta: dict, depth_path: str):
    """The recording, completed where it lacks what the depth file's run used: its intrinsics and, for a run at a
    constant velocity (``tofnet run --velocity``), the poses that velocity implies (the camera's frame at the
    first event is the world's; no rotation). Each one taken is said on stderr."""
    import dataclasses

    import numpy as np

    from tofnet.cli.export import run_camera
    from tofnet.eval.views import has_poses
    from tofnet.io.groundtruth import Trajectory

    changes = {}
    if recording.intrinsics is None and (intrinsics := run_camera(meta, depth_path)) is not None:
        changes["intrinsics"] = intrinsics
        print(f"camera: the run's, from {depth_path} (fx {intrinsics.fx:g}, fy {intrinsics.fy:g} px)", file=sys.stderr)
    velocity = (meta.get("summary") or {}).get("velocity_m_s")
    if not has_poses(recording.trajectory) and velocity is not None and len(recording.events):
        start_s, end_s = recording.events["t"][0] * 1e-6, recording.events["t"][-1] * 1e-6 + 1.0
        v = np.asarray(velocity, dtype=np.float64)
        changes["trajectory"] = Trajectory([start_s, end_s], [np.zeros(3), v * (end_s - start_s)],
                                           [[0.0, 0.0, 0.0, 1.0]] * 2, source=f"{depth_path}: velocity {list(v)} m/s")
        print(f"poses: the run's constant velocity ({', '.join(f'{c:g}' for c in v)} m/s, camera frame), from "
              f"{depth_path}", file=sys.stderr)
    return dataclasses.replace(recording, **changes) if changes else recording


def handle_units(args) -> int:
    """``tofnet plot units REC [--pixel X,Y] [--window 0.1:0.15]``."""
    import numpy as np

    from tofnet.api import constant_velocity, load_network
    from tofnet.eval.plots import save_figure
    from tofnet.eval.units import unit_traces, units_figure
    from tofnet.io import read_recording
    from tofnet.units import seconds

    from tofnet.cli.inputs import camera_options, sequence_options
    from tofnet.io.ecd import recording_files
    from tofnet.io.files import check_output
    out = Path(args.out) if args.out else Path(args.recording).with_name(Path(args.recording).stem + "_units.png")
    if out.suffix.lower() != ".png":
        raise TofnetError(f"--out: figures are written as PNG, got {out.name!r}")
    check_output(out, force=args.force, inputs=recording_files(args.recording), what="the units figure")
    recording = read_recording(args.recording, allow_external=args.allow_external, **sequence_options(args),
                               **camera_options(args))
    network, _, _, _ = load_network(args.spec, sensor_size=None if args.spec else recording.sensor_size,
                                    allow_import=args.allow_import)
    if args.velocity:
        constant_velocity(network, args.velocity)
    start, end = 0.1, 0.15
    if args.window:
        if ":" not in args.window:
            raise TofnetError(f"--window for units: expected START:END in seconds since the start, got {args.window!r}")
        a, b = args.window.split(":", 1)
        start, end = seconds(a, "--window start"), seconds(b, "--window end")
    t = recording.events["t"]
    if args.pixel:
        try:
            pixels = [tuple(int(v) for v in text.split(",")) for text in args.pixel]
        except ValueError:
            raise TofnetError(f"--pixel: expected X,Y, got {args.pixel}") from None
        if any(len(p) != 2 for p in pixels):
            raise TofnetError(f"--pixel: expected X,Y, got {args.pixel}")
    else:  # the busiest pixel of the window
        inside = (t >= t[0] + start * 1e6) & (t < t[0] + end * 1e6)
        width = int(recording.events["x"].max()) + 1
        flat = recording.events["y"][inside].astype(np.int64) * width + recording.events["x"][inside]
        if not len(flat):
            raise TofnetError(f"no events in the window {start:g}..{end:g} s")
        busiest = int(np.bincount(flat).argmax())
        pixels = [(busiest % width, busiest // width)]
    traces = unit_traces(recording, network, pixels, start, end, backend=args.backend or "fixed")
    print(save_figure(units_figure(traces), out))
    return 0
