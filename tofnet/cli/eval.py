"""``tofnet eval``: accuracy of depth estimates against the recording's per-event ground truth."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, TofnetError, quote


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "eval", help="accuracy of depth estimates against ground truth",
        description="Match each depth estimate to the input event that triggered it (same pixel, "
                    "latency_steps earlier) and report the paper's errors (mean and median absolute [m] "
                    "and relative [%]), coverage and unmatched estimates, overall and per time window. "
                    "The recording needs ground-truth depth: per event (events_depth.npy, e.g. from "
                    "`tofnet simulate`) or as frames (a DSEC, MVSEC or M3ED sequence: each estimate is scored "
                    "against the frames at its own pixel and time), with the mean absolute error at 10, 20 and 30 m "
                    "cut-offs.")
    p.add_argument("recording", help="the recording the depth was computed from (ECD folder or events file)")
    p.add_argument("depth", help="depth estimates written by `tofnet run` (.npz; .csv with --timestep)")
    p.add_argument("--window", default="100ms",
                   help="length of the per-window metrics, e.g. 100ms or 0.5 (seconds); 0 for none (default 100ms)")
    p.add_argument("--quality", metavar="FILE",
                   help="the fits behind the estimates (the *.quality.npz `tofnet run` writes beside the depth of "
                        "the time-surface estimator; found there by default): error and coverage against a "
                        "threshold on the fit's rms residual and on its points")
    p.add_argument("--json", metavar="OUT", help="also write the metrics as JSON to OUT ('-' for stdout only)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    add_timing_options(p)
    p.add_argument("--frames", choices=("nearest", "interpolate"), default="nearest",
                   help="ground truth as frames (DSEC disparity, MVSEC/M3ED depth images): the frame nearest to the "
                        "estimate's time, or the two around it interpolated (default nearest)")
    from tofnet.cli.inputs import add_allow_external, add_sequence_options, add_window_options
    add_window_options(p)
    add_allow_external(p)
    add_sequence_options(p)
    p.set_defaults(handler=handle)


def add_timing_options(p: argparse.ArgumentParser) -> None:
    """Timing for depth files that do not carry it (``.csv``); shared with ``tofnet plot``."""
    g = p.add_argument_group("timing (only needed for depth files without it, such as .csv)")
    g.add_argument("--timestep", help="the run's timestep, e.g. 1ms")
    g.add_argument("--latency-steps", type=int, help="output step minus input step (2 for the paper's network)")


def load_inputs(recording_path: str, depth_path: str, *, timestep: str | None = None,
                latency_steps: int | None = None, window=None, allow_external: bool = False,
                side: str | None = None, rectify: bool = False, **camera):
    """Read a recording and a depth file; complete the depth timing from the options.

    Returns ``(recording, depth, meta)``. The options fill what the file lacks and must
    agree with what it has; ``t0_us`` is then recovered from the stamps
    (``t = t0 + (step + 1) * dt``). With a time ``window`` only its events are read and
    only the estimates whose input step lies in it are kept. ``side`` and ``rectify`` open a dataset
    sequence folder as the run did; ``camera``: ``intrinsics``, ``calib``, ``camera`` (``camera_options``).
    """
    from tofnet.io import read_depth
    from tofnet.io.depth import MAX_LATENCY_STEPS, check_timing
    from tofnet.io.source import open_recording
    from tofnet.units import microseconds, seconds

    depth, meta = read_depth(depth_path)
    meta = dict(meta)
    summary = meta.get("summary") or {}
    ran = _window_of_run(summary, depth_path)
    # the run's own time window, when it had one: its events, not the whole recording's; a window asked here
    # too is cut to the run's once the file's first event (which relative times count from) is known
    own, window = (window, None) if window is not None and ran is not None else (None, window or ran)
    side, rectify, taken = _sequence_of_run(summary, depth_path, side, rectify)
    reading = summary.get("reading_size")  # the run's --sensor-size: the file read as far as the run read it
    reading = tuple(reading) if isinstance(reading, list) and len(reading) == 2 and all(
        type(v) is int and 0 < v <= 1 << 16 for v in reading) else None
    with open_recording(recording_path, window=window, allow_external=allow_external, side=side,
                        rectify=rectify, reading_size=reading, **camera) as source:
        if own is not None:
            source.set_window(_common_window(source, own, summary["window_us"], depth_path))
        recording = source.read()
        bounds = source.window
    for note in taken:
        _note(note)
    if recording.sensor_size is not None and len(depth):
        width, height = (max(a, b) for a, b in zip(recording.sensor_size, reading or (0, 0)))
        outside = (depth["x"] >= width) | (depth["y"] >= height)
        if np.any(outside):
            raise DataError(f"{depth_path}: {int(outside.sum()):,} of its {len(depth):,} estimates lie outside "
                            f"{recording_path}'s {width}x{height} sensor: is it this recording's depth?")
    given = {}
    from tofnet.units import MAX_PERIOD_S
    if timestep is not None:
        given["timestep_us"] = microseconds(seconds(timestep, "--timestep", limit=MAX_PERIOD_S))
        if given["timestep_us"] <= 0:
            raise TofnetError(f"--timestep must be positive, got {quote(timestep)}")
    if latency_steps is not None:
        if not 0 <= latency_steps <= MAX_LATENCY_STEPS:
            raise TofnetError(f"--latency-steps: expected 0..{MAX_LATENCY_STEPS}, got {latency_steps}")
        given["latency_steps"] = int(latency_steps)
    for key, value in given.items():
        if meta.get(key) is not None and int(meta[key]) != value:
            raise DataError(f"{depth_path}: the file says {key} = {meta[key]}, the option says {value}")
        meta[key] = value
    check_timing(depth_path, depth, meta)  # a .csv's steps with --timestep, as a .npz's were when read
    if meta.get("t0_us") is None and meta.get("timestep_us") is not None:
        meta["t0_us"] = _t0_from_stamps(depth, int(meta["timestep_us"]), recording, depth_path)
    if bounds is not None:
        depth = _estimates_in_window(depth, meta, *bounds, depth_path)
    elif mismatch := _run_on_another_recording(meta.get("summary") or {}, len(recording.events)):
        import logging
        logging.getLogger("tofnet.cli").warning(f"warning: {depth_path} {mismatch}")
    return recording, depth, meta


def _sequence_of_run(summary: dict, depth_path: str, side: str | None, rectify: bool) -> tuple:
    """A dataset sequence read as the run read it (``--side``, ``--rectify``, recorded in the depth file), so the
    estimates meet the events and ground truth at the pixels they were made at: ``(side, rectify, notes)``.
    A side asked here other than the run's is refused (its depth is another camera's)."""
    ran = summary.get("sequence")
    ran = ran if isinstance(ran, dict) else {}
    ran_side, ran_rectify, notes = ran.get("side"), ran.get("rectify") is True, []
    if ran_side in ("left", "right") and side is None:
        side = ran_side
        notes.append(f"the {side} camera, as the run read it (from {depth_path})")
    elif ran_side in ("left", "right") and side != ran_side:
        raise DataError(f"{depth_path}: the run read the {ran_side} camera; --side {side} scores another camera's "
                        "events against its depth")
    if ran_rectify and not rectify:
        rectify = True
        notes.append(f"events rectified, as the run read them (--rectify, from {depth_path})")
    return side, rectify, notes


def _note(text: str) -> None:
    """A note on stderr (``tofnet eval: note: ...``, through the command's log handler), not in the report."""
    import logging
    logging.getLogger("tofnet.cli").info(f"note: {text}")


def _common_window(source, own, ran: list, depth_path: str):
    """The part of the window asked (``own``, a ``TimeWindow``) that the run read too (``ran``: its ``window_us``):
    the estimates come from those events alone, so coverage over the others would count events the run never
    saw. A note says when the window asked is cut; ``DataError`` when the two do not overlap."""
    from tofnet.io.window import parse_window

    first = source.first_time()
    if first is None:
        raise DataError(f"{source.path}: no events")
    start, stop = own.resolve(first)
    common = (max(start, ran[0]), min((t for t in (stop, ran[1]) if t is not None), default=None))

    def text(bounds) -> str:
        return (f"{(bounds[0] - first) * 1e-6:g} .. "
                f"{'the end' if bounds[1] is None else f'{(bounds[1] - first) * 1e-6:g} s'} from the first event")
    if common[1] is not None and common[1] <= common[0]:
        raise DataError(f"{depth_path}: its run read {text(ran)}; the window asked ({own.text()}: {text((start, stop))}) "
                        "is outside it")
    if common != (start, stop):
        _note(
            f"scoring {text(common)}: the window asked ({own.text()}) cut to the run's ({text(ran)}), whose "
            f"events alone {depth_path}'s estimates come from")
    return parse_window(start=f"@{common[0]}us", until=None if common[1] is None else f"@{common[1]}us")


def _window_of_run(summary: dict, depth_path: str):
    """The time window (absolute µs on the file's clock) a depth file's ``tofnet run`` read, else None."""
    from tofnet.io.window import parse_window
    if "window_us" not in summary:
        return None
    bounds = summary["window_us"]
    problem = f"{depth_path}: its summary's window_us is not [start, stop] in µs (stop null: the end)"
    if not (isinstance(bounds, list) and len(bounds) == 2 and type(bounds[0]) is int
            and (bounds[1] is None or type(bounds[1]) is int)):
        raise DataError(problem)
    start, stop = bounds
    try:
        return parse_window(start=f"@{start}us", until=None if stop is None else f"@{stop}us")
    except TofnetError as err:
        raise DataError(f"{problem}: {err}") from None


def _run_on_another_recording(summary: dict, events: int) -> str | None:
    """What says a depth file's run read other events than ``events`` (its whole recording's, no window on either
    side), or None."""
    ran_on, events_in = summary.get("recording"), summary.get("events_in")
    notes = summary.get("notes") if isinstance(summary.get("notes"), list) else []
    if type(events_in) is not int or events_in == events or any("time window" in str(n) for n in notes):
        return None
    return (f"was run on {events_in:,} events ({str(ran_on)!r}), this recording has {events:,}: "
            "is it this recording's depth?")


def _estimates_in_window(depth: np.ndarray, meta: dict, start: int, stop: int | None, depth_path: str) -> np.ndarray:
    """The estimates whose input step (``step - latency_steps``) overlaps ``[start, stop)`` µs."""
    if meta.get("t0_us") is None or meta.get("timestep_us") is None or meta.get("latency_steps") is None:
        raise DataError(f"{depth_path}: a time window needs the run's timing (give --timestep and --latency-steps)")
    dt = int(meta["timestep_us"])
    step_start = int(meta["t0_us"]) + (depth["step"].astype(np.int64) - int(meta["latency_steps"])) * dt
    keep = step_start + dt > start
    if stop is not None:
        keep &= step_start < stop
    return depth[keep]


def _t0_from_stamps(depth: np.ndarray, timestep_us: int, recording, depth_path: str) -> int:
    if len(depth) == 0:
        return int(recording.events["t"][0]) if len(recording.events) else 0
    t0 = depth["t"] - (depth["step"] + 1) * timestep_us
    if np.any(t0 != t0[0]):
        raise DataError(f"{depth_path}: stamps do not fit t = t0 + (step + 1) * {timestep_us} µs; "
                        f"is --timestep the run's timestep?")
    return int(t0[0])


def quality_curves(args, depth, result) -> dict | None:
    """Error and coverage against fit-quality thresholds, when the estimates' fits are at hand."""
    from tofnet.eval.quality import CRITERIA, check_aligned, quality_beside, quality_curve, read_quality

    path = Path(args.quality) if args.quality else quality_beside(args.depth)
    if path is None:
        return None
    quality = read_quality(path)
    check_aligned(depth, quality, str(path))
    return {c: quality_curve(depth, quality, result.matches, result.events_in, c) for c in CRITERIA}


def handle(args) -> int:
    from tofnet.eval import evaluate
    from tofnet.units import seconds

    window_s = seconds(args.window, "--window")
    if window_s < 0:
        raise TofnetError(f"--window must be 0 or positive, got {quote(args.window)}")
    if args.json and args.json != "-":
        from tofnet.io.ecd import recording_files
        from tofnet.io.files import check_output
        check_output(args.json, force=args.force, inputs=[*recording_files(args.recording), Path(args.depth)],
                     what="--json")
    from tofnet.cli.inputs import sequence_options, window_option
    recording, depth, meta = load_inputs(args.recording, args.depth, timestep=args.timestep,
                                         latency_steps=args.latency_steps, window=window_option(args),
                                         allow_external=args.allow_external, **sequence_options(args))
    undistortion = (meta.get("summary") or {}).get("undistortion")
    if undistortion and recording.frame_gt is not None and recording.frame_gt.pixel_map is not None:
        raise DataError(f"{args.depth}: the estimates are at undistorted pixels, the ground truth is placed through "
                        "the rectification map from raw pixels; run with --rectify and a network without an "
                        "undistort process instead")
    if undistortion:  # the estimates are at undistorted pixels: match them to events moved there too
        from tofnet.eval.undistorted import lens_from_summary, undistorted_recording
        before = len(recording.events)
        recording = undistorted_recording(recording, *lens_from_summary(undistortion))
        if len(recording.events) < before:  # as the run's undistort process did (its counts say so too)
            _note(f"{before - len(recording.events):,} of {before:,} events leave the undistorted image and are not "
                  "scored (the run's undistort process left them out too)")
    result = evaluate(recording, depth, meta, window_s=window_s, interpolate=args.frames == "interpolate")
    from tofnet.eval.rotation import format_share_split, split_by_true_share
    shares, what = split_by_true_share(recording, depth, result)
    data = result.to_dict()
    data["share_split"] = None if shares is None else [{k: (v if np.isfinite(v) else None) for k, v in row.items()}
                                                       for row in shares]
    data["share_split_note"] = what
    from tofnet.eval.breakdown import by_depth_band, by_motion_phase, format_groups
    bands = by_depth_band(depth, result.matches, recording.gt_depth)
    phases = None if recording.trajectory is None else by_motion_phase(depth, result.matches, recording.events,
                                                                       recording.trajectory)
    data["depth_bands"] = [g.to_dict() for g in bands]
    curves = quality_curves(args, depth, result)
    data["quality_curves"] = None if curves is None else {k: [p.to_dict() for p in c] for k, c in curves.items()}
    data["motion_phases"] = None if phases is None else [g.to_dict() for g in phases]
    text = json.dumps(data, indent=2, allow_nan=False)
    if args.json == "-":
        print(text)
        return 0
    print(result.table())
    print()
    print(format_share_split(shares, what) if shares is not None else f"error by translational share: not available ({what})")
    print()
    print(format_groups("by true depth (coverage: estimates over the band's events)", bands))
    print()
    print(format_groups("by motion phase (reversal: turned > 90 deg in 100 ms, or slow)", phases) if phases is not None
          else "by motion phase: not available (the recording has no poses)")
    for criterion, curve in (curves or {}).items():
        from tofnet.eval.quality import format_curve
        print()
        print(format_curve(criterion, curve))
    if args.json:
        from tofnet.io.files import write_text_atomic
        write_text_atomic(args.json, text + "\n")
        print(f"wrote {args.json}", file=sys.stderr)
    return 0
