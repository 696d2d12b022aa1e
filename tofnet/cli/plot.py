"""``tofnet plot``: figures of depth estimates (depth map, histogram, error over time, 3D cloud)."""

from __future__ import annotations

import sys
from pathlib import Path

from tofnet.cli.eval import add_timing_options, load_inputs
from tofnet.errors import DataError, TofnetError

KIND_HELP = {
    "depthmap": "depth per pixel accumulated over a window, beside the ground truth (paper Fig. 5, 6)",
    "histogram": "histogram of the estimated depths over that of the ground truth (Fig. 4)",
    "error": "camera trajectory and windowed relative error over time (Fig. 3)",
    "cloud": "estimates back-projected to 3D with the camera path (Fig. 1)",
    "all": "every figure the recording supports",
}


def register(subparsers) -> None:
    kinds = "; ".join(f"{k}: {v}" for k, v in KIND_HELP.items())
    p = subparsers.add_parser("plot", help="figures of depth estimates (PNG)",
                              description=f"Draw depth estimates as PNG figures. Kinds - {kinds}.")
    p.add_argument("kind", choices=tuple(KIND_HELP), help="which figure")
    p.add_argument("recording", help="the recording the depth was computed from (ECD folder or events file)")
    p.add_argument("depth", help="depth estimates written by `tofnet run` (.npz)")
    p.add_argument("--out", help="PNG to write (a folder for 'all'); default: next to DEPTH, "
                                 "named <depth>_<kind>.png")
    p.add_argument("--window", metavar="START:END|LENGTH",
                   help="time span, seconds since the start: '1.2:1.27', '1200ms:1270ms', or a length "
                        "centred in the run, '70ms' (default: 70ms for depthmap, the whole run otherwise)")
    p.add_argument("--error-window", default="100ms", help="window of the error-over-time figure (default 100ms)")
    p.add_argument("--reduce", choices=("latest", "median"), default="latest",
                   help="depth map: each pixel's latest or median depth in the window (default latest)")
    p.add_argument("--no-gt", action="store_true", help="leave out the ground truth panels and overlays")
    p.add_argument("--force", action="store_true", help="overwrite existing PNG files")
    add_timing_options(p)
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.eval.metrics import require_timing
    from tofnet.eval.plots import available_kinds, figure, save_figure
    from tofnet.io.ecd import recording_files
    from tofnet.io.files import check_output
    from tofnet.units import seconds

    window_s = seconds(args.error_window, "--error-window")
    if window_s <= 0:
        raise TofnetError(f"--error-window must be positive, got {args.error_window!r}")
    recording, depth, meta = load_inputs(args.recording, args.depth, timestep=args.timestep,
                                         latency_steps=args.latency_steps)
    require_timing(meta)
    options = {"window": args.window, "window_s": window_s, "reduce": args.reduce, "with_gt": not args.no_gt}
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
