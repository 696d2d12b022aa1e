"""``tofnet export``: depth estimates to files other tools load (depth maps, point clouds)."""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import TofnetError, quote


def register(subparsers) -> None:
    p = subparsers.add_parser("export", help="depth estimates to dense depth maps (.npy, 16-bit PNG) and .ply",
                              description="Turn the depth events of 'tofnet run' into dense H x W depth maps "
                                          "per time window (float32 metres .npy, age map .npy, 16-bit PNG in "
                                          "millimetres; --no-age and --no-png leave those out) and/or a point "
                                          "cloud (.ply) in the camera or world frame. The maps' size is checked "
                                          "against the free space before the first is written.")
    p.add_argument("depth", help="depth file written by 'tofnet run' (.npz or .csv)")
    p.add_argument("--recording", help="the recording the depth came from (intrinsics, poses, sensor size); "
                                       "default: the one named in the depth file's summary")
    p.add_argument("--maps", metavar="DIR", help="write depth_<k>.npy, age_<k>.npy, depth_<k>.png and index.csv")
    p.add_argument("--window", default="10ms", help="time window per map, e.g. 10ms (default 10ms)")
    p.add_argument("--max-age", help="keep a pixel's estimate in later windows while younger than this "
                                     "(default: the window)")
    p.add_argument("--no-png", action="store_true", help="maps as .npy only")
    p.add_argument("--no-age", action="store_true", help="no age maps (age_<k>.npy): half the .npy bytes")
    p.add_argument("--ply", metavar="FILE", help="write the estimates as a point cloud")
    p.add_argument("--frame", choices=("camera", "world"), default="camera",
                   help="point cloud frame: camera (OpenCV axes) or world (needs poses); default camera")
    p.add_argument("--pixels", choices=("raw", "undistorted"), default=None,
                   help="whether the estimates' pixels are raw sensor pixels (the lens distortion is undone "
                        "before back-projecting) or already undistorted; default: what the depth file says "
                        "(a network with an undistort process moves its spikes), else raw")
    p.add_argument("--ascii", action="store_true", help="ASCII .ply instead of binary little-endian")
    p.add_argument("--no-color", action="store_true", help="no depth colours in the .ply")
    p.add_argument("--sensor-size", metavar="WxH", help="map size in pixels (default: the recording's)")
    p.add_argument("--force", action="store_true", help="replace existing maps and .ply (never an input)")
    from tofnet.cli.inputs import add_allow_external, add_camera_options, add_window_options
    add_camera_options(p)
    add_window_options(p)
    add_allow_external(p)
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.cli.inputs import camera_options, sensor_size_option, window_option
    from tofnet.core.params import parse_size
    from tofnet.io.depth import read_depth
    from tofnet.units import microseconds, seconds

    if not args.maps and not args.ply:
        raise TofnetError("nothing to do: give --maps DIR and/or --ply FILE")
    check_export_outputs(args)
    depth, meta = read_depth(args.depth)
    recording_path = args.recording or (meta.get("summary") or {}).get("recording")
    if recording_path is not None and not (isinstance(recording_path, str) and recording_path):
        raise TofnetError(f"{args.depth}: its summary's recording is not a path; pass --recording PATH")
    recording, bounds = None, None
    window = window_option(args)
    if recording_path:
        from tofnet.io.source import open_recording
        try:
            with open_recording(recording_path, window=window, allow_external=args.allow_external,
                                reading_size=sensor_size_option(args), **camera_options(args)) as source:
                # The camera only; the events only when the sensor size must come from their extent.
                recording = source.metadata(imu=False) if source.sensor_size is not None else source.read()
                bounds = source.window
        except TofnetError as err:
            if args.recording:
                raise
            # the depth file chose this path: its reader's message may quote the file, so say only that
            raise TofnetError(f"cannot read the recording {quote(recording_path)} that {args.depth} names "
                              f"({type(err).__name__}); pass --recording PATH to read it and see why") from None
        check_export_outputs(args)  # the files it read (groundtruth.txt, ...) are inputs too
    elif args.ply or not args.sensor_size or window is not None:
        raise TofnetError("--recording is needed (the depth file does not name its recording)")
    if bounds is not None:
        start, stop = bounds
        depth = depth[(depth["t"] >= start) & ((depth["t"] < stop) if stop is not None else True)]
        meta = {**meta, "t0_us": start}  # maps count their windows from the window's start
    sensor = parse_size(args.sensor_size, "--sensor-size") if args.sensor_size else \
        (recording.sensor_size or (240, 180))
    intrinsics = recording.intrinsics if recording is not None else None
    if args.ply:  # what the point cloud needs, checked before any map is written
        if intrinsics is None:
            intrinsics = run_camera(meta, args.depth)
            if intrinsics is None:
                raise TofnetError("a point cloud needs the camera intrinsics: the recording has none and the depth "
                                  "file names none; pass --intrinsics FX,FY,CX,CY or --calib FILE")
            print(f"camera         the run's, from {args.depth} (fx {intrinsics.fx:g}, fy {intrinsics.fy:g} px)")
        if args.frame == "world" and recording.trajectory is None:
            raise TofnetError("--frame world needs the recording's poses (groundtruth.txt or the file's pose stream)")
    if args.maps:
        from tofnet.io.maps import depth_maps, write_depth_maps
        window_us = microseconds(seconds(args.window, "--window"))
        if window_us <= 0:
            raise TofnetError(f"--window: expected a positive duration (one map per window), got {args.window!r}")
        max_age_us = microseconds(seconds(args.max_age, "--max-age")) if args.max_age else None
        if meta.get("t0_us") is None and len(depth):  # a .csv: a .npz's windows count from its run's t0
            print(f"note           {args.depth} holds no t0: the windows start at its first estimate "
                  f"({int(depth['t'][0]) * 1e-6:.6f} s); the .npz of the same run starts them at the run's t0")
        maps = depth_maps(depth, sensor, window_us, t0_us=meta.get("t0_us"), max_age_us=max_age_us,
                          source=args.depth)
        check_maps_space(args, maps)
        done = write_depth_maps(maps, args.maps, png=not args.no_png, age=not args.no_age)
        empty = done["empty_windows"]
        print(f"maps           {done['windows']:,} windows of {args.window} with depth -> {Path(args.maps)}/ (index.csv"
              + (f"; {empty:,} windows between them without any, not written)" if empty else ")"))
        if done["saturated_png_pixels"]:
            print(f"warning        {done['saturated_png_pixels']:,} PNG pixels beyond 65.535 m written as 65535")
    if args.ply:
        from tofnet.io.ply import depth_colors, depth_points, write_ply
        points = depth_points(depth, intrinsics, recording.trajectory, frame=args.frame,
                              raw_pixels=pixels_of(args.pixels, meta) == "raw")
        colors = None if args.no_color else depth_colors(depth["z"])
        written = write_ply(args.ply, points, colors=colors, binary=not args.ascii,
                            comment=f"tofnet depth from {args.depth}, {args.frame} frame, metres")
        skipped = len(points) - written
        print(f"point cloud    {written:,} points ({args.frame} frame) -> {args.ply}"
              + (f"; {skipped:,} skipped (pixel without undistortion)" if skipped else ""))
    return 0


def pixels_of(option: str | None, meta: dict) -> str:
    """``--pixels``, else ``undistorted`` when the depth file records an undistortion, else ``raw``."""
    if option is not None:
        return option
    return "undistorted" if (meta.get("summary") or {}).get("undistortion") else "raw"


def check_export_outputs(args) -> None:
    """``--ply`` and ``--maps`` like every output (``tofnet.io.files.check_output``): never
    an input (the depth file, the recording's files, and every file read so far), and a
    ``--maps`` folder only when new, empty, or an earlier export's (with ``--force``).
    Run before any work, and again once the recording is read (its side files)."""
    from tofnet.io.ecd import recording_files
    from tofnet.io.files import check_output

    from tofnet.io.files import lies_in

    inputs = [Path(args.depth)] + (recording_files(args.recording) if args.recording else [])
    if args.ply and args.maps and lies_in(args.ply, args.maps):  # the maps folder is replaced as a whole
        raise TofnetError(f"--ply {args.ply}: inside the --maps folder {args.maps}, which holds the maps only; "
                          "choose a name outside it")
    if args.ply:
        check_output(args.ply, force=args.force, inputs=inputs, what="--ply")
    if args.maps:
        check_output(args.maps, force=args.force, inputs=inputs, what="--maps", folder=True)



def check_maps_space(args, maps) -> None:
    """Refuse, before the first map is written, maps that need more than the free space of ``--maps``' file
    system (``tofnet.io.files.free_bytes``; the folder is written whole before it replaces an earlier one)."""
    from tofnet.errors import DataError, located
    from tofnet.io.files import MIN_FREE_BYTES, free_bytes
    from tofnet.units import format_bytes

    each = maps.map_bytes(age=not args.no_age, png=not args.no_png)
    needed, free = maps.windows * each + MIN_FREE_BYTES, free_bytes(args.maps)
    if free is not None and needed > free:
        width, height = maps.size
        kept = " + ".join(["depth .npy"] + (["age .npy"] if not args.no_age else [])
                          + (["PNG (counted uncompressed)"] if not args.no_png else []))
        raise DataError(located(args.maps, None, f"--maps: {maps.windows:,} maps of {width}x{height} px need up to "
                                                 f"{format_bytes(needed)} ({format_bytes(each)} each: {kept}), the "
                                                 f"file system has {format_bytes(free)} free; give a longer --window, "
                                                 "--no-age, --no-png, or --ply alone (a point cloud)"))


def run_camera(meta: dict, depth_path: str):
    """The camera a depth file's run used (``tofnet run`` records it in its summary), or None when it names
    none; checked as ``--intrinsics`` is (the depth file may come from someone else): one line otherwise."""
    import math

    from tofnet.io.recording import Intrinsics
    camera = (meta.get("summary") or {}).get("camera")
    if camera is None:
        return None
    try:
        fx, fy, cx, cy = (float(v) for v in camera["intrinsics"])
        model = camera.get("distortion_model") or "radtan"
        distortion = tuple(float(v) for v in camera.get("distortion") or ())
        counts = {"radtan": (0, 5), "equidistant": (0, 4)}.get(model)
        if counts is None or len(distortion) not in counts:
            raise ValueError(f"lens {model!r} with {len(distortion)} coefficients")
        if not all(math.isfinite(v) for v in (fx, fy, cx, cy, *distortion)) or not (fx > 0 and fy > 0):
            raise ValueError("fx, fy > 0 and finite numbers expected")
        return Intrinsics(fx, fy, cx, cy, distortion, model)
    except (TypeError, KeyError, ValueError, AttributeError) as err:
        raise TofnetError(f"{depth_path}: its summary's camera is not one tofnet run writes ({str(err)[:80]}); pass "
                          "--intrinsics FX,FY,CX,CY or --calib FILE") from None
