"""``tofnet live``: the network on events as they arrive (a camera, or a file replayed at its speed),
with the depth map shown and the delay of every estimate measured."""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path

from tofnet.errors import TofnetError
from tofnet.units import format_steps


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "live", help="run on a live camera or a replayed recording, showing depth and measuring the delay",
        description="Feed the depth network 1 ms packets as they arrive, from a camera (through faery) or a "
                    "recording replayed at its recorded speed; show the depth map (a window where there is a "
                    "display, else PNGs with --out) and print the delay from an event to its estimate (p50/p99).",
        conflict_handler="resolve")
    from tofnet.cli.inputs import add_input_options
    from tofnet.cli.run import add_network_options, add_workers_option

    add_network_options(p)
    add_input_options(p)  # its --camera (a --calib file's camera) is replaced by the live camera below
    g = p.add_argument_group("source")
    which = g.add_mutually_exclusive_group(required=True)
    which.add_argument("--replay", metavar="FILE", help="replay a recording (any format 'tofnet info' reads)")
    which.add_argument("--camera", dest="live_camera", action="store_true",
                       help="read the camera connected to this computer through faery (Prophesee, iniVation)")
    g.add_argument("--speed", type=float, default=1.0, help="replay speed, times the recorded speed (default 1)")
    g.add_argument("--drop-when-late", action="store_true",
                   help="drop the events of a packet fed more than --late-tolerance late (counted); default: "
                        "fall behind and say by how much")
    g.add_argument("--late-tolerance", default=None, metavar="T",
                   help="with --drop-when-late: how late a packet is fed before its events are dropped "
                        "(default 100ms: above the stalls of a run that keeps up on average)")
    g.add_argument("--seconds", default=None, help="stop after this much wall time, e.g. 10 or 30s")
    v = p.add_argument_group("display")
    v.add_argument("-o", "--out", metavar="DIR",
                   help="write PNG frames of the depth map into the folder DIR instead of opening a window; DIR "
                        "must be new or empty, or (with --force) an earlier live run's, which is replaced when "
                        "the run ends")
    v.add_argument("--png-every", default="0.5s", metavar="T", help="time between PNG frames (default 0.5s)")
    v.add_argument("--keep", default="0.2s", metavar="T",
                   help="how long a pixel's estimate stays shown (default 0.2s of source time)")
    v.add_argument("--no-view", action="store_true", help="no window: statistics only (and the PNG frames of --out)")
    p.add_argument("--backend", default=None, help="backend name (default: the spec's, else 'fixed')")
    add_workers_option(p)
    p.add_argument("--json", metavar="FILE", help="write the statistics as JSON")
    p.add_argument("--force", action="store_true", help="overwrite existing output files (never an input)")
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.api import DEFAULT_BACKEND, rotation_line
    from tofnet.cli.inputs import camera_options, input_options, sensor_size_option
    from tofnet.backends.runtime import clock_of
    from tofnet.cli.run import backend_choice, build_network
    from tofnet.cli.run_summary import reader_lines, warning_lines, workers_line
    from tofnet.io.files import atomic_path, write_text_atomic
    from tofnet.units import seconds
    from tofnet.live import CameraSource, ReplaySource, run_live
    from tofnet.live_view import DepthMap, PngFolder, Window, has_display

    png_every, keep = seconds(args.png_every, "--png-every"), seconds(args.keep, "--keep")
    if png_every <= 0 or keep <= 0:
        raise TofnetError("--png-every and --keep must be longer than 0 s")
    wall_limit = None if args.seconds is None else seconds(args.seconds, "--seconds")
    if wall_limit is not None and wall_limit <= 0:
        raise TofnetError(f"--seconds: expected a time longer than 0 s, got {args.seconds}")
    late_tolerance_us = late_tolerance_option(args)
    check_live_outputs(args)  # before the source is opened: a refused output costs no run
    opened = None
    if args.replay:
        from tofnet.io.source import open_recording
        opened = open_recording(args.replay, reading_size=sensor_size_option(args), **input_options(args))
        meta = opened.metadata()
        origin = str(args.replay)
        if meta.sensor_size is None and not args.sensor_size:
            # as tofnet run reads such a file (whole): its reader may size it by the events' extent (a note says so)
            whole = opened.read()
            opened.sensor_size, notes = whole.sensor_size, whole.notes
            del whole  # the replay reads the file again: its events are not kept through it
            meta = opened.metadata()
            meta.notes = notes
    else:
        camera = camera_options(args)
        source = CameraSource(camera["intrinsics"])
        meta = source.metadata()
        origin = "camera"
    interrupted = None
    with contextlib.ExitStack() as frames_folder:  # --out: written under a temporary name, put in place at the end
        try:
            network, compile_options, spec_backend, backend_options = build_network(args, meta.sensor_size, meta)
            from tofnet.cli.outputs import network_files
            check_live_outputs(args, network_files(network))  # the side files and the network's files read now
            step_us = clock_of(network).timestep_us
            if args.replay:
                source = ReplaySource(opened, speed=args.speed, packet_us=step_us)
            else:
                source.packet_us = step_us
            backend, backend_options = backend_choice(args, spec_backend, backend_options, DEFAULT_BACKEND)
            depth = DepthMap(network.sensor_size, keep_s=keep)
            view, note = None, None
            if args.out:
                folder = frames_folder.enter_context(atomic_path(args.out, folder=True, written_by="tofnet live"))
                view = PngFolder(folder, depth, png_every, shown_as=args.out)
            elif not args.no_view:
                if has_display():
                    view = Window(depth, title=f"tofnet live: {origin}")
                else:
                    note = "no display: give --out DIR for PNG frames of the depth map"
            stop = None if wall_limit is None else _stop_after(wall_limit)
            try:
                stats, result = run_live(source, network, backend=backend, backend_options=backend_options,
                                         compile_options=compile_options, drop_when_late=args.drop_when_late,
                                         late_tolerance_us=late_tolerance_us,
                                         on_depth=depth.add if view else None, tick=view.tick if view else None,
                                         stop=stop)  # no view: no map to keep up
            except KeyboardInterrupt as err:
                if not isinstance(view, PngFolder):
                    raise
                # A second Ctrl-C (the first ends the run with its summary, run_live): the whole frames
                # written so far are kept.
                view.stop()
                interrupted = err
            except BaseException:
                if isinstance(view, PngFolder):
                    view.stop()  # the frame being written is finished; its thread ends; the folder is removed
                raise
        finally:
            if opened is not None:
                opened.close()
        if interrupted is None:
            how = f"replay at {args.speed:g}x" if args.replay else "camera"
            print(f"source         {origin} ({how}, {network.sensor_size[0]}x{network.sensor_size[1]} px, packets of "
                  f"{step_us / 1000:g} ms)")
            latency = result.latency.get(result.depth_outputs[0], 0) if result.depth_outputs else 0
            print(f"backend        {backend}; depth latency {format_steps(latency)} ({latency * step_us / 1000:g} ms)")
            rotation = rotation_line(network, meta, no_rotation=getattr(args, "no_rotation", False))
            if rotation:  # as tofnet run says it: where eq. 7's ω comes from, or why it is not compensated
                print(f"rotation       {rotation}")
            split = result.summary().get("workers")
            if split:  # how the work was split
                print(f"workers        {workers_line(split)}")
            for line in reader_lines(result.summary()):  # where every event went, as tofnet run says it
                print(line)
            print(f"depth out      {stats.depth_out:,}")
            for line in stats.lines():
                print(line)
            for line in warning_lines(result.summary(), result, network.sensor_size):  # as tofnet run warns
                print(line)
            shown = view.close() if view is not None else None
    if interrupted is not None:
        print(f"view           {view.summary()} (interrupted)")
        raise interrupted
    if shown is not None:
        print(f"view           {shown}")
    for line in list(meta.notes) + ([note] if note else []):
        print(f"note           {line}")
    if args.json:
        write_text_atomic(args.json, json.dumps(summary_of(stats), indent=2) + "\n")
    if stats.interrupted:  # 130 as for any interrupted command: the run did not end by itself or --seconds
        print("tofnet live: interrupted (Ctrl-C); the summary covers the run up to it", file=sys.stderr)
        return 130
    return 0


def check_live_outputs(args, more_inputs: list | None = None) -> None:
    """Refuse, before any work, a ``--json`` that exists (without ``--force``) or is an input, an ``--out``
    that is not a new or empty folder or (with ``--force``) one an earlier live run wrote, and the two
    naming the same place. Run again once the network is built (``more_inputs``: the files it reads)."""
    from tofnet.io.ecd import recording_files
    from tofnet.io.files import check_output, distinct_outputs, lies_in

    inputs = (recording_files(args.replay) if args.replay else []) + ([Path(args.spec)] if args.spec else [])
    inputs += more_inputs or []
    distinct_outputs({"--out": args.out, "--json": args.json})
    if args.out and args.json and lies_in(args.json, args.out):
        raise TofnetError(f"--json {args.json}: lies in the --out folder {args.out}, which holds only the frames "
                          "tofnet live writes; choose a name outside it")
    if args.out:
        check_output(args.out, force=args.force, inputs=inputs, what="--out", folder=True)
    if args.json:
        check_output(args.json, force=args.force, inputs=inputs, what="--json")


def late_tolerance_option(args) -> float:
    """``--late-tolerance`` in µs (``live.LATE_TOLERANCE_US`` when not given); only with ``--drop-when-late``."""
    from tofnet.live import LATE_TOLERANCE_US
    from tofnet.units import seconds

    if args.late_tolerance is None:
        return LATE_TOLERANCE_US
    if not args.drop_when_late:
        raise TofnetError("--late-tolerance: expected with --drop-when-late (it says when a late packet is dropped)")
    value = seconds(args.late_tolerance, "--late-tolerance")
    if value < 0:
        raise TofnetError(f"--late-tolerance: expected a time of 0 s or more, got {args.late_tolerance}")
    return value * 1e6


def _stop_after(limit_s: float):
    """A ``stop()`` that turns true ``limit_s`` seconds after its first call (the first packet)."""
    import time
    started = []

    def stop() -> bool:
        if not started:
            started.append(time.perf_counter())
        return time.perf_counter() - started[0] >= limit_s
    return stop


def summary_of(stats) -> dict:
    """The statistics as plain numbers (delays in ms)."""
    return {"delay_p50_ms": stats.percentile_ms(50), "delay_p99_ms": stats.percentile_ms(99),
            "delay_max_ms": stats.percentile_ms(100), "estimates": stats.delays.count,
            "events_in": stats.events_in, "wall_s": stats.wall_s, "cpu_s": stats.cpu_s, "source_s": stats.span_us * 1e-6,
            "speed": stats.speed, "cpu_percent_of_one_core": stats.cpu_percent(),
            "events_per_s": stats.events_in / stats.wall_s if stats.wall_s else 0.0, "packets": stats.packets,
            "late_packets": stats.late_packets, "max_behind_ms": stats.max_behind_us * 1e-3,
            "behind_at_end_ms": stats.behind_us * 1e-3, "dropped_events": stats.dropped_events,
            "dropped_packets": stats.dropped_packets, "depth_out": stats.depth_out, "catch_up_batches": stats.batches,
            "late_tolerance_ms": None if stats.late_tolerance_us is None else stats.late_tolerance_us * 1e-3,
            "interrupted": stats.interrupted}
