"""``tofnet live``: the network on events as they arrive (a camera, or a file replayed at its speed),
with the depth map shown and the delay of every estimate measured."""

from __future__ import annotations

import json
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
                   help="drop the events of a packet fed more than one packet late (counted); default: fall "
                        "behind and say by how much")
    g.add_argument("--seconds", type=float, default=None, help="stop after this many seconds of wall time")
    v = p.add_argument_group("display")
    v.add_argument("-o", "--out", metavar="DIR", help="write PNG frames of the depth map into DIR (new, empty, or an "
                                                "earlier live run's) instead of opening a window")
    v.add_argument("--png-every", default="0.5s", metavar="T", help="time between PNG frames (default 0.5s)")
    v.add_argument("--keep", default="0.2s", metavar="T",
                   help="how long a pixel's estimate stays shown (default 0.2s of source time)")
    v.add_argument("--no-view", action="store_true", help="no window and no PNGs: statistics only")
    p.add_argument("--backend", default=None, help="backend name (default: the spec's, else 'fixed')")
    add_workers_option(p)
    p.add_argument("--json", metavar="FILE", help="write the statistics as JSON")
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.api import DEFAULT_BACKEND
    from tofnet.cli.inputs import camera_options, input_options
    from tofnet.backends.runtime import clock_of
    from tofnet.cli.run import backend_choice, build_network, workers_line
    from tofnet.units import seconds
    from tofnet.live import CameraSource, ReplaySource, run_live
    from tofnet.live_view import DepthMap, PngFolder, Window, check_png_folder, has_display

    png_every, keep = seconds(args.png_every, "--png-every"), seconds(args.keep, "--keep")
    if png_every <= 0 or keep <= 0:
        raise TofnetError("--png-every and --keep must be longer than 0 s")
    if args.out:
        check_png_folder(Path(args.out))
    opened = None
    if args.replay:
        from tofnet.io.source import open_recording
        opened = open_recording(args.replay, **input_options(args))
        meta = opened.metadata()
        origin = str(args.replay)
    else:
        camera = camera_options(args)
        source = CameraSource(camera["intrinsics"])
        meta = source.metadata()
        origin = "camera"
    try:
        network, compile_options, spec_backend, backend_options = build_network(args, meta.sensor_size, meta)
        step_us = clock_of(network).timestep_us
        if args.replay:
            source = ReplaySource(opened, speed=args.speed, packet_us=step_us)
        else:
            source.packet_us = step_us
        backend, backend_options = backend_choice(args, spec_backend, backend_options, DEFAULT_BACKEND)
        depth = DepthMap(network.sensor_size, keep_s=keep)
        view, note = None, None
        if args.out:
            view = PngFolder(args.out, depth, png_every)
        elif not args.no_view:
            if has_display():
                view = Window(depth, title=f"tofnet live: {origin}")
            else:
                note = "no display: give --out DIR for PNG frames of the depth map"
        stop = None if args.seconds is None else _stop_after(args.seconds)
        try:
            stats, result = run_live(source, network, backend=backend, backend_options=backend_options,
                                     compile_options=compile_options, drop_when_late=args.drop_when_late,
                                     on_depth=depth.add if view else None, tick=view.tick if view else None,
                                     stop=stop)  # no view: no map to keep up
        except BaseException:
            if isinstance(view, PngFolder):
                view.stop()  # the frame being written is finished; its thread ends
            raise
    finally:
        if opened is not None:
            opened.close()
    how = f"replay at {args.speed:g}x" if args.replay else "camera"
    print(f"source         {origin} ({how}, {network.sensor_size[0]}x{network.sensor_size[1]} px, packets of "
          f"{step_us / 1000:g} ms)")
    latency = result.latency.get(result.depth_outputs[0], 0) if result.depth_outputs else 0
    print(f"backend        {backend}; depth latency {format_steps(latency)} ({latency * step_us / 1000:g} ms)")
    split = result.summary().get("workers")
    if split:  # how the work was split
        print(f"workers        {workers_line(split)}")
    print(f"depth out      {stats.depth_out:,}")
    for line in stats.lines():
        print(line)
    if view is not None:
        print(f"view           {view.close()}")
    if note:
        print(f"note           {note}")
    if args.json:
        from tofnet.io.files import write_text_atomic
        write_text_atomic(args.json, json.dumps(summary_of(stats), indent=2) + "\n")
    return 0


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
            "delay_max_ms": stats.percentile_ms(100), "estimates": len(stats.delays_us),
            "events_in": stats.events_in, "wall_s": stats.wall_s, "cpu_s": stats.cpu_s, "source_s": stats.span_us * 1e-6,
            "events_per_s": stats.events_in / stats.wall_s if stats.wall_s else 0.0, "packets": stats.packets,
            "late_packets": stats.late_packets, "max_behind_ms": stats.max_behind_us * 1e-3,
            "behind_at_end_ms": stats.behind_us * 1e-3, "dropped_events": stats.dropped_events,
            "dropped_packets": stats.dropped_packets, "depth_out": stats.depth_out, "catch_up_batches": stats.batches}
