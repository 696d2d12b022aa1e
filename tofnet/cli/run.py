"""``tofnet run``: a recording in, depth events out, and a summary of what happened to every event."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

from tofnet.errors import BackendError, quote
from tofnet.cli.run_summary import format_summary


def register(subparsers) -> None:
    p = subparsers.add_parser("run", help="estimate depth from a recording",
                              description="Run the depth network on an event recording (an ECD folder or any "
                                          "format 'tofnet info' reads) and write depth events.")
    p.add_argument("recording", help="ECD folder (events.txt, calib.txt, groundtruth.txt) or event file "
                                     "(.txt .npy .npz .aedat4 .raw .dat .es .h5 .bag)")
    add_network_options(p)
    from tofnet.cli.inputs import add_input_options
    add_input_options(p)
    p.add_argument("-o", "--out", default="depth.npz", help="depth output, .npz or .csv (default: depth.npz); several depth outputs go to "
                                                     "OUT.<process>.npz/.csv, other outputs and probes to "
                                                     "OUT.<process>.<port>.npz (records, always .npz)")
    p.add_argument("--backend", default=None, help="backend name (default: the spec's, else 'fixed'); "
                                                    "see 'tofnet conformance --list'")
    add_workers_option(p)
    p.add_argument("--record-tot", action="store_true",
                   help="also save the time-of-travel spikes (next to --out, *_tot.npz)")
    p.add_argument("--probe", action="append", default=[], metavar="PROCESS.PORT", type=probe_option,
                   help="also save what an output port sent (next to --out: OUT.PROCESS.PORT.npz); repeatable")
    p.add_argument("--monitor", action="append", default=[], metavar="PROCESS.VAR[@X,Y;...]",
                   help="record a state variable (or a port) at the start of every step, optionally at chosen "
                        "pixels (next to --out: OUT.monitor.PROCESS.VAR.npz); repeatable; runs model by model")
    p.add_argument("--monitor-every", type=int, default=1, metavar="K", help="sample monitors every K steps")
    p.add_argument("--json", metavar="FILE", help="write the run summary as JSON")
    p.add_argument("--force", action="store_true", help="overwrite existing output files (never an input)")
    p.add_argument("--quiet", action="store_true", help="no progress, summary only")
    p.set_defaults(handler=handle)


def add_workers_option(p: argparse.ArgumentParser) -> None:
    """``--workers N|auto`` (shared with ``tofnet live``)."""
    p.add_argument("--workers", default=None, metavar="N|auto",
                   help="CPU cores to run on: the sensor is cut into N bands of rows (fixed, float; multiproc: "
                        "worker processes); 0 or auto: one per CPU (default: the spec's, else 1)")


def backend_choice(args: argparse.Namespace, spec_backend: str | None, spec_options: dict,
                   default: str) -> tuple[str, dict]:
    """The backend ``--backend`` or the spec names (else ``default``) and its options: the spec's when it is
    the spec's backend, with ``--workers``."""
    backend = args.backend or spec_backend or default
    options = {} if args.backend and args.backend != spec_backend else dict(spec_options)
    if args.workers is not None:
        options["workers"] = workers_option(args.workers)
    return backend, options


def workers_option(text: str) -> int | str:
    """``--workers``: a whole number, or ``auto``; more than the CPUs runs as asked (the bands of rows are
    the same, a test may want more than the machine has), with one warning line saying so."""
    from tofnet.machine import cpu_count
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        raise BackendError(f"--workers: expected a whole number of workers or auto, got {text!r}") from None
    if value < 0:
        raise BackendError(f"--workers: expected a whole number of workers >= 0 (0 or auto: one per CPU), got {value}")
    if value > cpu_count():
        logging.getLogger("tofnet.cli").warning(f"warning: --workers: {value} workers on this machine's {cpu_count()} "
                                                f"CPUs: at most {cpu_count()} run at once")
    return value


def probe_option(text: str) -> str:
    """``--probe``'s value: ``PROCESS.PORT``, two names (it names a file beside ``--out``)."""
    import re
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_]*", text):
        raise argparse.ArgumentTypeError(f"expected PROCESS.PORT (two names), got {quote(text, 40)}")
    return text


def add_network_options(p: argparse.ArgumentParser) -> None:
    """Options that choose and adjust the network (shared with ``tofnet demo``)."""
    g = p.add_argument_group("network")
    g.add_argument("--spec", help="YAML network spec (default: the --estimator's network)")
    from tofnet.cli.trust import add_allow_import
    add_allow_import(g)
    g.add_argument("--estimator", choices=("paper", "improved"), default=None,
                   help="built-in network: paper (the default: the paper's network) or improved (the time-surface "
                        "estimator, beyond the paper: docs/time_surface.md)")
    g.add_argument("--sensor-size", metavar="WxH",
                   help="sensor size in pixels (default: the recording's, else 240x180); smaller than the recording's: "
                        "a crop (the events outside are counted); larger: the file's stated size is taken as wrong")
    g.add_argument("--timestep", help="timestep, e.g. 1ms or 0.001 (seconds)")
    g.add_argument("--refractory", help="refractory period, e.g. 5ms; 0 disables")
    g.add_argument("--distance", type=int, help="pixels between facilitating and trigger pixel")
    g.add_argument("--counter-bits", type=int, help="time-of-travel counter width")
    g.add_argument("--velocity-per", choices=("patch", "pixel"), help="A t per patch (paper) or per pixel")
    g.add_argument("--update-every", type=int, help="steps between velocity updates")
    g.add_argument("--velocity", metavar="TX,TY,TZ",
                   help="constant camera velocity in m/s (camera frame) instead of the ground-truth poses")
    g.add_argument("--patch", metavar="WxH|auto", help="core patch size for the compiler (default: the spec's or auto)")
    g.add_argument("--no-rotation", action="store_true",
                   help="keep the paper's eq. 8 even when the recording has rotation information (turning poses "
                        "or imu.txt), which the default network compensates (eq. 7)")
    g.add_argument("--no-undistort", action="store_true",
                   help="treat the camera as a pinhole even when the recording's calibration has lens "
                        "distortion, which the velocity process otherwise takes into account")
    g.add_argument("--set", metavar="PROCESS.PARAM=VALUE", action="append", default=[], dest="set_params",
                   help="set one parameter of one process, as a spec would (units as there), after the options "
                        "above, e.g. --set time_surface.burst_surfaces=4 or --set input.refractory=5ms; repeatable")


def set_parameters(network, items) -> None:
    """``--set PROCESS.PARAM=VALUE`` (each value read as a YAML scalar or list: ``4``, ``5ms``, ``[0.5, 0, 0]``),
    converted and checked as the spec's would be. The items of one process are set together and checked once
    (``apply_overrides``), so that parameters which need each other (``velocity.source=samples`` and
    ``velocity.samples=FILE``) work in any order; every mistake is one line naming the option(s)."""
    import yaml

    from tofnet.api import apply_overrides
    from tofnet.errors import NetworkError

    by_process: dict[str, dict[str, tuple[str, object]]] = {}
    for item in items:
        name, equals, text = item.partition("=")
        process, dot, param = _setting(item).partition(".")
        if not (equals and dot and process and param and text.strip()):
            raise NetworkError(f"--set {item!r}: expected PROCESS.PARAM=VALUE, e.g. time_surface.burst_surfaces=4 "
                               f"(null clears an optional parameter)")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        by_process.setdefault(process, {})[param] = (item, value)
    for process, params in by_process.items():
        try:
            apply_overrides(network, **{f"{process}.{param}": value for param, (_, value) in params.items()})
        except NetworkError as err:
            # a value that does not convert names its field: that option; a check of several, all of them
            named = [item for param, (item, _) in params.items() if str(err).startswith(f"{process}.{param}:")]
            named = named or [item for item, _ in params.values()]
            raise NetworkError(f"{' '.join(f'--set {item}' for item in named)}: {err}") from None


def run_intrinsics(network, recording):
    """The camera the run used: its velocity process's (a spec's ``intrinsics:`` and lens win over the
    recording's calibration), else the recording's; None when neither has one."""
    from tofnet.errors import TofnetError
    from tofnet.models.binding import camera_of as camera_seen
    from tofnet.processes import VelocityProcess
    for process in network.of_type(VelocityProcess):
        try:
            return camera_seen(process.intrinsics, process.distortion_model, process.distortion, recording,
                               process.name)
        except TofnetError:
            break
    return recording.intrinsics


def camera_of(intrinsics) -> dict | None:
    """What a depth file's summary records of the camera the run used (``tofnet export`` back-projects
    with it when the recording has none): ``[fx, fy, cx, cy]`` px and the lens, or None."""
    if intrinsics is None:
        return None
    return {"intrinsics": [intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy],
            "distortion_model": intrinsics.distortion_model, "distortion": list(intrinsics.distortion)}


def _setting(item: str) -> str:
    """``PROCESS.PARAM`` of a ``--set`` item (blanks around the names dropped)."""
    return ".".join(part.strip() for part in item.partition("=")[0].partition(".")[::2])


def sensor_size_note(stated, network_size, given_size) -> str:
    """Why the network's sensor differs from the one the file states (px): a crop, or a header said too small."""
    (sw, sh), (nw, nh) = stated, network_size
    by = f"--sensor-size {given_size[0]}x{given_size[1]}" if given_size else "the network's sensor_size (spec)"
    if nw <= sw and nh <= sh:
        return (f"the file states a {sw}x{sh} px sensor; {by} runs {nw}x{nh} px of it (a crop: the events outside "
                "are counted out_of_bounds)")
    return f"the file states a {sw}x{sh} px sensor; {by} runs {nw}x{nh} px (events read up to it)"


def build_network(args, recording_sensor_size, recording=None):
    """The network the options describe, and the compile options and backend it names."""
    from tofnet.api import apply_overrides, constant_velocity, load_network
    from tofnet.core.params import parse_size  # the same WxH parsing as the spec

    sensor = parse_size(args.sensor_size, "--sensor-size") if args.sensor_size else None
    network, compile_options, spec_backend, backend_options = load_network(
        Path(args.spec) if args.spec else None, sensor_size=sensor or (None if args.spec else recording_sensor_size),
        recording=recording, rotation=not getattr(args, "no_rotation", False),
        undistort=not getattr(args, "no_undistort", False), estimator=getattr(args, "estimator", None),
        allow_import=args.allow_import, replaced=[_setting(item) for item in getattr(args, "set_params", None) or ()]
        + (["VelocityProcess.samples"] if args.velocity else []))  # --velocity makes every velocity constant
    from tofnet.errors import NetworkError
    options = dict(timestep=args.timestep, refractory=args.refractory, distance=args.distance,
                   counter_bits=args.counter_bits, velocity_per=args.velocity_per, update_every=args.update_every)
    for option, value in [*options.items(), ("velocity", args.velocity)]:  # each error names the option typed
        try:
            if option == "velocity" and value:
                constant_velocity(network, value)
            elif option != "velocity":
                apply_overrides(network, **{option: value})
        except NetworkError as err:
            flag = f"--{option.replace('_', '-')}"
            raise NetworkError(str(err) if str(err).startswith(flag) else f"{flag}: {err}") from None
    set_parameters(network, getattr(args, "set_params", None) or ())
    if args.patch:
        compile_options["patch"] = "auto" if args.patch == "auto" else parse_size(args.patch, "--patch")
    stated = recording.sensor_size if recording is not None else None
    if recording is not None and not (stated and any(n < s for n, s in zip(network.sensor_size, stated))):
        # the camera against the sensor the network runs (a file that states no size was not checked when
        # opened); not against a crop of the file's sensor, where a principal point outside is expected
        from tofnet.io.plausible import principal_point_note
        note = principal_point_note(run_intrinsics(network, recording), network.sensor_size)
        if note and note not in recording.notes:
            recording.notes.append(note)
    return network, compile_options, spec_backend, backend_options


def handle(args) -> int:
    from tofnet.api import DEFAULT_BACKEND, rotation_line, run, run_source, undistortion_of
    from tofnet.cli.inputs import input_options, sensor_size_option, sequence_options
    from tofnet.cli.outputs import check_more_outputs, check_run_outputs
    from tofnet.cli.progress import Progress
    from tofnet.io.source import open_recording
    from tofnet.kernels.compilation import Stopwatch
    from tofnet.monitor import Monitor

    clock = Stopwatch()
    check_run_outputs(args)
    monitors = [Monitor.parse(text, args.monitor_every) for text in args.monitor]
    # --sensor-size is the network's; a header that states a smaller sensor is read up to it (reading_size)
    given_size = sensor_size_option(args)
    with clock.reading():  # opening: a numpy, text or ECD file is loaded whole and checked here
        source = open_recording(args.recording, reading_size=given_size, **input_options(args))
    with source:
        for topic, doubt in [] if args.quiet else source.doubts:  # before a run that may be long because of it
            if not (topic == "poses" and args.velocity):  # --velocity: the poses are not used
                print(f"tofnet run: note: {doubt}", file=sys.stderr)
        # where the file does not say its size, --sensor-size is it (not the events' extent, nor a note that it
        # is); where the file says a smaller one, its header is wrong; a smaller --sensor-size is a crop
        stated = source.sensor_size  # the file's own (None: it does not say)
        if given_size and (source.sensor_size is None or any(g > f for g, f in zip(given_size, source.sensor_size))):
            source.sensor_size = given_size
        # A file that says its sensor size (or given one) streams through the network in chunks (events
        # never all in memory); otherwise the size comes from the events' extent, which needs them all.
        streaming = source.sensor_size is not None and not monitors
        with clock.reading():
            recording = source.metadata() if streaming else source.read()
        network, compile_options, spec_backend, backend_options = build_network(args, recording.sensor_size,
                                                                                 recording)
        check_run_outputs(args, network)  # again: the files the recording, the spec and the network read
        backend, backend_options = backend_choice(args, spec_backend, backend_options, DEFAULT_BACKEND)
        progress = None if args.quiet else Progress(f"tofnet run [{backend}]")
        options = dict(backend=backend, backend_options=backend_options, compile_options=compile_options,
                       record_tot=args.record_tot, probes=args.probe, progress=progress)
        if streaming:
            result, compiled = run_source(source, network, spill_dir=Path(args.out).resolve().parent, **options)
        else:
            result, compiled = run(recording, network, monitors=monitors, **options)
    if progress:
        progress.done()
    out = Path(args.out)
    summary = result.summary()
    summary["recording"] = str(args.recording)
    if source.window is not None:  # absolute µs: eval and plot read the same events (tofnet.cli.eval.load_inputs)
        summary["window_us"] = list(source.window)
    if given_size:  # and read the file as far as this run did
        summary["reading_size"] = list(given_size)
    summary["rotation"] = rotation_line(network, recording, no_rotation=getattr(args, "no_rotation", False))
    summary["undistortion"] = undistortion_of(network, recording, result, str(args.recording),
                                              no_undistort=getattr(args, "no_undistort", False))
    summary["notes"] = list(recording.notes)
    if stated is not None and tuple(stated) != tuple(network.sensor_size):
        summary["stated_sensor_size"] = list(stated)
        summary["notes"].append(sensor_size_note(stated, network.sensor_size, given_size))
    if args.velocity:  # checked by constant_velocity; the poses it implies place `tofnet plot cloud`'s estimates
        summary["velocity_m_s"] = [float(v) for v in args.velocity.split(",")]
        if not any(summary["velocity_m_s"]):
            summary["notes"].append(f"--velocity {args.velocity}: no translation, so no depth (depth from event "
                                    "timing needs the camera to translate)")
    summary["camera"] = camera_of(run_intrinsics(network, recording))
    reading = {key: value for key, value in sequence_options(args).items() if value}
    if reading:  # how a dataset sequence was read (a side, rectified): eval and plot read it the same way
        summary["sequence"] = reading
    summary["total_time_s"] = time.perf_counter() - clock.started
    summary["compile_time_s"], summary["kernels_compiled"] = clock.compile_seconds, clock.compiled
    # the parts add up to the whole: reading counts the file opened and read before the run too (a .npy
    # loaded and checked whole), set-up all else but the network's time and the kernels' (the network built
    # and compiled, its state, workers started, outputs checked)
    summary["read_time_s"] += clock.reading_seconds
    summary["setup_time_s"] = max(0.0, summary["total_time_s"] - summary["wall_time_s"] - summary["read_time_s"]
                                  - summary["compile_time_s"])
    written = write_outputs(out, result, summary, args.record_tot, check=lambda paths: check_more_outputs(args, paths))
    summary["files"] = {name: str(path) for name, path in written.items()}
    print(format_summary(summary, result, written, network_width=network.sensor_size))
    for note in summary["notes"]:
        print(f"note           {note}")
    if args.json:
        from tofnet.io.files import write_text_atomic
        write_text_atomic(args.json, json.dumps(summary, indent=2) + "\n")
    return 0


def write_outputs(out: Path, result, summary: dict, record_tot: bool, check=None) -> dict[str, Path]:
    """Write every depth output (``OUT``, or ``OUT.<process>.npz`` when there are several) and every
    probe (``OUT.<process>.<port>.npz``); the time-of-travel spikes of ``--record-tot`` to ``OUT_tot.npz``.
    ``check(paths)``, when given, sees every file name before anything is written.
    Returns output name -> file."""
    from tofnet.api import lens_of_run
    from tofnet.io.depth import write_depth
    from tofnet.io.npy import write_npz

    depth_names = result.depth_outputs
    paths: dict[str, Path] = {}
    for name in depth_names:
        paths[name] = out if len(depth_names) == 1 else out.with_name(f"{out.stem}.{name.split('.')[0]}{out.suffix}")
    for name in result.outputs:
        if name in paths:
            continue
        if record_tot and result.payloads.get(name) == "count" and len(depth_names) == 1:
            paths[name] = out.with_name(out.stem + "_tot.npz")
        else:
            paths[name] = out.with_name(f"{out.stem}.{name}.npz")
    for monitor in result.extra.get("monitors", []):
        paths[f"monitor {monitor.target}"] = out.with_name(f"{out.stem}.monitor.{monitor.target}.npz")
    if check is not None:
        check(list(paths.values()))
    monitors = {f"monitor {m.target}": m for m in result.extra.get("monitors", [])}
    for name, path in paths.items():
        if name in monitors:
            write_npz(path, monitors[name].arrays(), compress=True)
            continue
        records = result.outputs[name]
        if name in depth_names:  # the run's facts only: the same input gives the same bytes on integer backends
            write_depth(path, records, t0_us=result.t0_us, timestep_us=result.timestep_us,
                        latency_steps=result.latency[name],
                        summary={**result.facts(), "recording": summary["recording"], "notes": summary["notes"],
                                 **{key: summary[key] for key in ("window_us", "reading_size", "velocity_m_s", "sequence")
                                    if key in summary},
                                 "undistortion": lens_of_run(summary.get("undistortion")),
                                 "camera": summary.get("camera")})
        else:
            write_npz(path, {field: records[field] for field in records.dtype.names}, compress=True)
    return paths

