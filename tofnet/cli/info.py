"""``tofnet info``: what a recording holds, read in chunks (any size, bounded memory)."""

from __future__ import annotations

import json

import numpy as np

from tofnet.cli.inputs import add_input_options, input_options


def register(subparsers) -> None:
    p = subparsers.add_parser("info", help="describe a recording (format, size, events, rate, streams)",
                              description="Read a recording in any supported format and print its format, "
                                          "sensor size, event count, duration, rate, polarity balance, "
                                          "calibration, poses, IMU and the other streams it holds.")
    p.add_argument("recording", help="ECD folder or event file (.txt .npy .npz .aedat4 .raw .dat .es .h5 .bag)")
    add_input_options(p)
    p.add_argument("--sensor-size", metavar="WxH", help="sensor size in pixels, when the file does not say")
    p.add_argument("--json", metavar="FILE", help="also write the facts as JSON")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json file (never an input)")
    p.add_argument("--quiet", action="store_true", help="no progress")
    p.set_defaults(handler=handle)


def describe(path, *, sensor_size=None, progress=None, opened=None, **options) -> dict:
    """The facts ``tofnet info`` prints, as plain data (one pass over the events);
    ``opened()``, when given, runs once the recording is open, before that pass."""
    from tofnet.io.source import open_recording

    with open_recording(path, sensor_size=sensor_size, **options) as source:
        if opened is not None:
            opened()
        count = on = 0
        t_first = t_last = None
        x_max = y_max = -1
        x_min = y_min = 1 << 16  # above any uint16 coordinate
        pixel_counts = None
        if source.sensor_size is not None:
            pixel_counts = np.zeros(source.sensor_size[0] * source.sensor_size[1], dtype=np.int64)
        assumed = _run_size(source)  # the file states no size: what tofnet run and live take, None: the extent
        beyond = 0
        for chunk in source.chunks(progress=progress):
            count += len(chunk)
            on += int(np.count_nonzero(chunk["p"]))
            t_first = int(chunk["t"][0]) if t_first is None else t_first
            t_last = int(chunk["t"][-1])
            x_max, y_max = max(x_max, int(chunk["x"].max())), max(y_max, int(chunk["y"].max()))
            x_min, y_min = min(x_min, int(chunk["x"].min())), min(y_min, int(chunk["y"].min()))
            if pixel_counts is not None:
                width, height = source.sensor_size
                inside = (chunk["x"] < width) & (chunk["y"] < height)
                beyond += len(chunk) - int(np.count_nonzero(inside))
                flat = chunk["y"][inside].astype(np.int64) * width + chunk["x"][inside]
                pixel_counts += np.bincount(flat, minlength=len(pixel_counts))
            elif assumed is not None:
                beyond += int(np.count_nonzero((chunk["x"] >= assumed[0]) | (chunk["y"] >= assumed[1])))
        duration = (t_last - t_first) * 1e-6 if count else 0.0
        facts = {
            "file": str(path), "format": source.describe(),
            "sensor_size": list(source.sensor_size) if source.sensor_size else None,
            # no size stated: the one tofnet run and live take (the default's, or the events' extent)
            "run_sensor_size": None if source.sensor_size or not (assumed or count)
            else list(assumed or (x_max + 1, y_max + 1)),
            "run_sensor_size_from": None if source.sensor_size else "default" if assumed else "extent",
            "events": count,
            "t_first_us": t_first, "t_last_us": t_last, "duration_s": duration,
            "rate_events_per_s": count / duration if duration > 0 else None,
            "on_fraction": on / count if count else None,
            "extent": [x_max + 1, y_max + 1] if count else None,
            "pixels_used": {"x": [x_min, x_max], "y": [y_min, y_max]} if count else None,
            "beyond_sensor": beyond if pixel_counts is not None or assumed is not None else None,
            "intrinsics": _intrinsics(source.intrinsics),
            "poses": _poses(source.trajectory),
            "imu_samples": int(len(source.imu)) if source.imu is not None else 0,
            "true_depth": source.has_depth,
            "streams": dict(source.streams),
            "notes": list(source.notes),
        }
        if pixel_counts is not None and count:
            busiest = int(np.argmax(pixel_counts))
            facts["busiest_pixel"] = {"x": busiest % source.sensor_size[0], "y": busiest // source.sensor_size[0],
                                      "events": int(pixel_counts[busiest])}
        return facts


def _run_size(source) -> tuple[int, int] | None:
    """For a file that states no sensor size and is read whole into memory (numpy, text, ECD), the size
    tofnet run and live take: the default network's (``DEFAULT_SENSOR_SIZE``); None otherwise (the
    other readers take the events' extent, ``EventSource.read``)."""
    from tofnet.io.in_memory import RecordingSource
    from tofnet.networks import DEFAULT_SENSOR_SIZE
    return DEFAULT_SENSOR_SIZE if source.sensor_size is None and isinstance(source, RecordingSource) else None


def _intrinsics(intrinsics) -> dict | None:
    if intrinsics is None:
        return None
    return {"fx": intrinsics.fx, "fy": intrinsics.fy, "cx": intrinsics.cx, "cy": intrinsics.cy,
            "distortion_model": intrinsics.distortion_model if intrinsics.distortion else None,
            "distortion": list(intrinsics.distortion)}


def _poses(trajectory) -> dict | None:
    if trajectory is None or not hasattr(trajectory, "times"):
        return None
    return {"count": len(trajectory.times), "t_first_s": float(trajectory.times[0]),
            "t_last_s": float(trajectory.times[-1])}


def format_facts(facts: dict) -> str:
    """The text ``tofnet info`` prints."""
    lines = [f"file           {facts['file']}", f"format         {facts['format']}"]
    size = facts["sensor_size"]
    if size:
        lines.append(f"sensor         {size[0]}x{size[1]} px")
    else:
        run = facts["run_sensor_size"]
        how = "the default" if facts["run_sensor_size_from"] == "default" else "the events' extent"
        taken = f"{run[0]}x{run[1]} px, {how}" if run else how
        lines.append(f"sensor         unknown (the file does not say); tofnet run and live take {taken}, "
                     "unless --sensor-size WxH")
    lines.append(f"events         {facts['events']:,}")
    if facts["events"]:
        lines.append(f"time           {facts['t_first_us'] * 1e-6:.6f} .. {facts['t_last_us'] * 1e-6:.6f} s "
                     f"({facts['duration_s']:.6g} s)")
        rate = facts["rate_events_per_s"]
        lines.append(f"rate           {rate / 1e6:.4g} M events/s (mean)" if rate else "rate           -")
        on = facts["on_fraction"]
        lines.append(f"polarity       ON {on:.1%} / OFF {1 - on:.1%}")
        used = facts["pixels_used"]
        beyond = facts["beyond_sensor"]
        lines.append(f"pixels used    x {used['x'][0]}..{used['x'][1]}, y {used['y'][0]}..{used['y'][1]}"
                     + (f"; {beyond:,} events beyond the sensor" if beyond and size else "")
                     + (f"; {beyond:,} events beyond {facts['run_sensor_size'][0]}x{facts['run_sensor_size'][1]} px"
                        if beyond and not size else ""))
        if "busiest_pixel" in facts:
            b = facts["busiest_pixel"]
            lines.append(f"busiest pixel  ({b['x']}, {b['y']}): {b['events']:,} events")
    k = facts["intrinsics"]
    if k:
        distortion = (f", {k['distortion_model']} distortion {', '.join(f'{c:.6g}' for c in k['distortion'])}"
                      if k["distortion"] else ", no distortion")
        lines.append(f"intrinsics     fx {k['fx']:.6g} fy {k['fy']:.6g} cx {k['cx']:.6g} cy {k['cy']:.6g}{distortion}")
    else:
        lines.append("intrinsics     none")
    poses = facts["poses"]
    lines.append(f"poses          {poses['count']:,} over {poses['t_first_s']:.6f} .. {poses['t_last_s']:.6f} s"
                 if poses else "poses          none")
    lines.append(f"imu            {facts['imu_samples']:,} samples" if facts["imu_samples"] else "imu            none")
    lines.append(f"true depth     {'yes' if facts['true_depth'] else 'no'}")
    for name, what in facts["streams"].items():
        lines.append(f"other stream   {name}: {what}")
    for note in facts["notes"]:
        lines.append(f"note           {note}")
    return "\n".join(lines)


def handle(args) -> int:
    from tofnet.cli.progress import Progress
    from tofnet.core.params import parse_size

    sensor = parse_size(args.sensor_size, "--sensor-size") if args.sensor_size else None
    check = None
    if args.json:
        from tofnet.io.ecd import recording_files
        from tofnet.io.files import check_output

        def check() -> None:  # before reading, and again once the side files (DSEC's calibration) are read
            check_output(args.json, force=args.force, inputs=recording_files(args.recording), what="--json")
        check()
    progress = None if args.quiet else Progress("tofnet info")
    facts = describe(args.recording, sensor_size=sensor, progress=progress, opened=check, **input_options(args))
    if progress:
        progress.done()
    print(format_facts(facts))
    if args.json:
        from tofnet.io.files import write_text_atomic
        write_text_atomic(args.json, json.dumps(facts, indent=2) + "\n")
    return 0
