"""``tofnet simulate``: a built-in scenario to an ECD folder with per-event ground-truth depth."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from tofnet.errors import TofnetError


def register(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="simulate an event camera moving through a scene",
                              description="Simulate a built-in scenario (ESIM-style event camera with "
                                          "ground-truth depth) and write an ECD folder: events.txt, calib.txt, "
                                          "groundtruth.txt, sensor_size.txt, events_depth.npy; or, for an OUT "
                                          "named .npz, .h5/.hdf5, .aedat4, .raw (EVT3), .dat or .es, that file, as "
                                          "'tofnet convert' writes it.")
    p.add_argument("scenario", nargs="?", help="scenario name (see --list)")
    p.add_argument("out_dir", nargs="?", metavar="OUT",
                   help="output folder (created if needed), or a .npz, .h5/.hdf5, .aedat4, .raw, .dat or .es "
                        "file")
    p.add_argument("--duration", type=float, metavar="S", help="seconds to simulate (default: 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of textures, thresholds and noise (default: 0)")
    p.add_argument("--sensor-size", metavar="WxH",
                   help="sensor size in pixels; the intrinsics scale to keep the field of view (default: 240x180)")
    p.add_argument("--list", action="store_true", help="list the scenarios and exit")
    p.add_argument("--json", metavar="FILE", help="also write the summary as JSON")
    p.add_argument("--force", action="store_true",
                   help="replace OUT_DIR (or the file) when tofnet wrote it before; never a folder holding other files")
    p.add_argument("--quiet", action="store_true", help="no progress, summary only")
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.sim import built_in_scenarios, scenario, simulate

    scenarios = built_in_scenarios()
    if args.list:
        print(list_scenarios())
        return 0
    if not args.scenario or not args.out_dir:
        raise TofnetError(f"expected SCENARIO and OUT_DIR; scenarios: {', '.join(scenarios)}")
    scenario(args.scenario)  # a one-line SimError for an unknown name or variant, before anything is written
    sensor = None
    if args.sensor_size:
        from tofnet.core.params import parse_size
        sensor = parse_size(args.sensor_size, "--sensor-size")
    out = Path(args.out_dir)
    as_file = is_file_output(out)
    if as_file:
        from tofnet.io.convert import check_convert_output
        check_convert_output(out, out.parent / f".{out.name}.simulated", force=args.force, gt_depth=True)
    else:
        from tofnet.io.files import check_output
        check_output(out, force=args.force, what="OUT_DIR", folder=True)
    if args.json:
        check_json(Path(args.json), out, as_file, args.force)
    progress = None
    if not args.quiet:
        from tofnet.cli.progress import Progress
        progress = Progress(f"simulate {args.scenario}", unit="renders")
    from tofnet.kernels.compilation import Stopwatch
    clock = Stopwatch()
    if as_file:
        summary = simulate_to_file(args.scenario, out, duration=args.duration, seed=args.seed, sensor_size=sensor,
                                   progress=progress, force=args.force)
    else:  # the whole folder under a temporary name, then in place of OUT_DIR (never mixed with older files)
        from tofnet.io.files import atomic_path
        with atomic_path(out, folder=True, written_by="tofnet simulate") as partial:
            summary = simulate(args.scenario, partial, duration=args.duration, seed=args.seed,
                               sensor_size=sensor, progress=progress)
        summary["out_dir"] = str(out)
    summary["compile_time_s"], summary["kernels_compiled"] = clock.compile_seconds, clock.compiled
    if progress is not None:
        progress.done()
    print(format_summary(summary))
    if args.json:
        from tofnet.io.files import write_text_atomic
        write_text_atomic(args.json, json.dumps(summary, indent=2) + "\n")
    return 0


def is_file_output(out: str | Path) -> bool:
    """Whether ``out`` names one file ``tofnet convert`` writes (``tofnet.io.convert.OUTPUTS``); any other
    name is an ECD folder."""
    from tofnet.io.convert import OUTPUTS

    return OUTPUTS.get(Path(out).suffix.lower(), "ecd") != "ecd"


def simulate_to_file(scenario: str, out: Path, *, force: bool, **options) -> dict:
    """Simulate into a temporary ECD folder beside ``out`` and convert it to ``out`` (its format by
    suffix, ``tofnet.io.convert``); the folder is removed. The summary's ``files`` say what went where."""
    import tempfile

    from tofnet.io.convert import convert
    from tofnet.io.source import open_recording
    from tofnet.sim import simulate

    parent = out.parent if str(out.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".tofnet-simulate-", dir=parent) as folder:
        summary = simulate(scenario, folder, **options)
        with open_recording(folder) as source:
            messages = convert(source, out, force=force)
    summary["out_dir"], summary["files"] = str(out), messages
    return summary


def check_json(json_path: Path, out: Path, as_file: bool, force: bool) -> None:
    """``--json`` is neither inside the folder written nor one of the files written (one line)."""
    from tofnet.io.convert import written_paths
    from tofnet.io.files import check_output, lies_in

    if as_file:
        clash = next((p for p in written_paths(out) if p.resolve() == json_path.resolve()), None)
        if clash is not None:
            raise TofnetError(f"--json {json_path}: the simulated recording writes {clash}; choose another name")
    elif lies_in(json_path, out):
        raise TofnetError(f"--json {json_path}: inside OUT_DIR {out}, which holds the recording only; "
                          "choose a name outside it")
    check_output(json_path, force=force, what="--json")


def list_scenarios() -> str:
    """One line per scenario: name, speed, what it does."""
    from tofnet.sim import built_in_scenarios

    lines = []
    for name, make in built_in_scenarios().items():
        config = make(1.0)
        speed = max((sum(v * v for v in s.velocity) ** 0.5 for s in config.trajectory.segments), default=0.0)
        lines.append(f"{name:14s} {speed:4.2f} m/s  {config.description}")
    return "\n".join(lines)


def format_summary(s: dict) -> str:
    """The summary ``simulate`` returns, as a few lines of text."""
    from tofnet.kernels.compilation import kernels
    w, h = s["sensor_size"]
    share_on = s["events_on"] / s["events"] if s["events"] else 0.0
    lines = [f"simulated {s['scenario']} ({s['description']}), seed {s['seed']}",
             f"  {s['duration_s']:.3f} s at {w}x{h} px: {s['events']:,} events ({share_on:.1%} ON), "
             f"{s['events_per_s'] / 1e6:.2f} M events/s",
             f"  event depth {s['depth_min']:.3f} .. {s['depth_max']:.3f} m (median {s['depth_median']:.3f} m)",
             f"  {s['renders']} renders, largest image step {s['max_render_step_px']:.3f} px; "
             f"{s['sim_time_s']:.1f} s simulating, {s['write_time_s']:.1f} s writing"
             + (f" ({s['compile_time_s']:.1f} s of it compiling {kernels(s['kernels_compiled'])}: first run only)"
                if s.get("kernels_compiled") else "")]
    if s["out_dir"] and is_file_output(s["out_dir"]):
        lines += [f"  {message}" for message in s["files"]]
    elif s["out_dir"]:
        lines.append(f"  wrote {s['out_dir']}: {' '.join(s['files'])}")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    from tofnet.cli import main
    sys.exit(main(["simulate", *sys.argv[1:]]))
