"""One call from a recording to depth: load a network, compile it, run a backend."""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path
from typing import Any, Iterable

from tofnet.backends.base import ProgressCallback, RunResult
from tofnet.core.network import Network
from tofnet.errors import NetworkError, TofnetError
from tofnet.io.recording import Recording
from tofnet.networks import DEFAULT_SENSOR_SIZE, depth_network, improved_network
from tofnet.processes import (AngularVelocityProcess, InputProcess, TimeOfTravelProcess, TimeSurfaceProcess,
                              UndistortProcess, VelocityProcess)

DEFAULT_BACKEND = "fixed"
#: The built-in estimators: the paper's network (the default) and the time-surface estimator
#: (``improved``: beyond the paper, docs/time_surface.md).
ESTIMATORS = {"paper": depth_network, "improved": improved_network}
DEFAULT_ESTIMATOR = "paper"


def rotation_source_of(recording: Recording | None) -> str | None:
    """The ``AngularVelocityProcess`` source for a recording's rotation information: ``"groundtruth"``
    for ground-truth poses that turn, else ``"gyro"`` for an IMU; None when it has neither
    (``tofnet.io.rotation.angular_velocity_of``)."""
    from tofnet.io.rotation import PoseAngularVelocity, angular_velocity_of

    found = angular_velocity_of(recording) if recording is not None else None
    if found is None:
        return None
    return "groundtruth" if isinstance(found, PoseAngularVelocity) else "gyro"


def lens_is_distorted(recording: Recording | None) -> bool:
    """True when the recording's calibration has a non-zero distortion coefficient."""
    intrinsics = recording.intrinsics if recording is not None else None
    return intrinsics is not None and any(c != 0 for c in intrinsics.distortion)


def default_network(recording: Recording | None = None, *, sensor_size: tuple[int, int] | None = None,
                    rotation: bool = True, estimator: str = DEFAULT_ESTIMATOR, undistort: bool = True) -> Network:
    """The ``estimator``'s network (``ESTIMATORS``: the paper's by default) sized to ``sensor_size``,
    else the recording's, else 240x180.

    When the recording has rotation information (``rotation_source_of``) and ``rotation`` is
    True, an angular velocity process feeds the depth neurons (or the time surface), which
    then compensate the camera's rotation (paper eq. 7); otherwise eq. 8 exactly.
    The velocity process sees the calibration's lens (``VelocityProcess``: ``A t`` through the
    lens, on raw pixels); ``undistort=False`` makes it ignore the lens (``ignore_lens``).
    """
    if estimator not in ESTIMATORS:
        raise NetworkError(f"estimator: expected one of {', '.join(ESTIMATORS)}, got {estimator!r}")
    size = sensor_size or (recording.sensor_size if recording is not None else None) or DEFAULT_SENSOR_SIZE
    source = rotation_source_of(recording) if rotation else None
    network = ESTIMATORS[estimator](size, rotation=None if source is None else {"source": source})
    if not undistort:
        ignore_lens(network)
    return network


def check_lens_once(network: Network, recording: Recording | None, source: str) -> None:
    """Refuse a network that would correct a distorted lens twice: spikes moved to undistorted
    pixels (an ``UndistortProcess``) and a velocity process that also takes the lens into account."""
    from tofnet.models.binding import camera_of

    moved = network.of_type(UndistortProcess)
    if not moved:
        return
    for process in network.of_type(VelocityProcess):
        try:
            camera = camera_of(process.intrinsics, process.distortion_model, process.distortion, recording,
                               process.name)
        except TofnetError:  # no calibration: the run says so
            continue
        if any(c != 0 for c in camera.distortion):
            raise NetworkError(f"{source}: process '{moved[0].name}' moves spikes to undistorted pixels and velocity "
                               f"process '{process.name}' also takes the lens into account; set distortion_model: "
                               "none on the velocity process (or remove the undistort process)")


def ignore_lens(network: Network) -> None:
    """Make every velocity process of ``network`` treat the camera as a pinhole (``--no-undistort``)."""
    for process in network.of_type(VelocityProcess):
        process.set_param("distortion", None)
        process.set_param("distortion_model", "none")


def rotation_summary(network: Network) -> str | None:
    """One line on where the depth neurons take the camera's rotation from; None when they compute eq. 8."""
    described = []
    for process in network.of_type(AngularVelocityProcess):
        if not process.b_w.targets:
            continue
        where = _rotation_source_text(process)
        targets = ", ".join(port.process.name for port in process.b_w.targets)
        described.append(f"{where} -> {targets}")
    return ("eq. 7, ω from " + "; ".join(described)) if described else None


def _rotation_source_text(process: AngularVelocityProcess) -> str:
    if process.source == "groundtruth":
        return "the ground-truth poses"
    if process.source == "gyro":
        turned = (" with its camera-IMU rotation" if process.rotation_cam_imu is not None
                  else "; its axes taken as the camera's, rad/s: rotation_cam_imu sets the IMU's")
        imu = process.imu or "the recording's IMU"
        return f"the gyroscope ({imu}{turned})"
    if process.source == "samples":
        return f"samples ({process.samples})"
    return f"a constant ω = {list(process.omega)} rad/s"


def rotation_line(network: Network, recording: Recording, no_rotation: bool = False) -> str | None:
    """Where the depth neurons take the camera's rotation from, or why they do not (None: nothing to say);
    ``no_rotation``: the user turned it off (``--no-rotation``)."""
    used = rotation_summary(network)
    if used is not None:
        return used
    found = rotation_source_of(recording)
    if found is None:
        return None
    why = "--no-rotation" if no_rotation else "the spec has no angular velocity process"
    return (f"not compensated (eq. 8: {why}), although the recording has "
            f"{'turning poses' if found == 'groundtruth' else 'a gyroscope (its IMU)'}")


def undistortion_of(network: Network, recording: Recording, result, recording_name: str,
                    no_undistort: bool = False) -> dict | None:
    """How the network treated the lens: through the velocity term (raw pixels), by moving spikes
    (an undistort process), or not at all; None when there is no lens to speak of. ``recording_name``
    names the recording in errors; ``no_undistort``: the user turned it off (``--no-undistort``)."""
    from tofnet.models.binding import camera_of
    from tofnet.processes import VelocityProcess

    found = network.of_type(UndistortProcess)
    if found:
        lens = found[0].lens(recording.intrinsics, recording_name)
        return {"ran": True, "process": found[0].name, "model": lens.distortion_model,
                "coefficients": list(lens.distortion), "intrinsics": [lens.fx, lens.fy, lens.cx, lens.cy],
                "sensor_size": list(found[0].sensor_size), "counts": dict(result.counts.get(found[0].name, {}))}
    for process in network.of_type(VelocityProcess):
        try:
            camera = camera_of(process.intrinsics, process.distortion_model, process.distortion, recording,
                               process.name)
        except TofnetError:
            continue
        if any(c != 0 for c in camera.distortion):
            return {"ran": True, "velocity": process.name, "model": camera.distortion_model,
                    "coefficients": list(camera.distortion)}
    if not lens_is_distorted(recording):
        return None
    why = "--no-undistort" if no_undistort else "the spec's velocity process ignores it"
    return {"ran": False, "why": why, "model": recording.intrinsics.distortion_model,
            "coefficients": list(recording.intrinsics.distortion)}


def lens_of_run(undistortion: dict | None) -> dict | None:
    """What a depth file records of the undistortion (``tofnet export`` and ``eval`` read it): the lens
    the estimates' pixels were moved with by an undistort process, or None for raw pixels."""
    if not (undistortion or {}).get("process"):
        return None
    return {key: undistortion[key] for key in ("model", "coefficients", "intrinsics", "sensor_size")}


def load_network(spec: str | Path | None = None, *, sensor_size: tuple[int, int] | None = None,
                 recording: Recording | None = None, rotation: bool = True, estimator: str | None = None,
                 undistort: bool = True, allow_import: Any = None, replaced: Iterable[str] = ()):
    """The network of a YAML spec (or the default network) and the spec's compile/backend settings.

    Returns ``(network, compile_options, backend_name_or_None, backend_options)``.
    ``sensor_size`` overrides the spec's (or the default's). Without a spec the network is
    ``default_network(recording, rotation=rotation)``; a spec decides for itself whether
    its depth neurons compensate rotation (``rotation=False`` refuses one that does) and whether
    it moves spikes to undistorted pixels (``undistort=False`` refuses one that does, and makes its
    velocity processes ignore the lens). ``estimator`` picks the built-in network (``ESTIMATORS``;
    None: the paper's); a spec names its own processes, so the two do not go together.
    ``allow_import``: the modules the spec's ``module:Class`` types may import (docs/spec.md); the
    spec's worker counts are capped to the CPU count (``tofnet.io.trust.cap_workers``). ``replaced``:
    the ``PROCESS.PARAM`` the caller sets afterwards (a file named there need not lie in the spec's folder).
    """
    if spec is None:
        network = default_network(recording, sensor_size=sensor_size, rotation=rotation,
                                   estimator=estimator or DEFAULT_ESTIMATOR, undistort=undistort)
        return network, {}, None, {}
    if estimator is not None:
        raise NetworkError(f"{spec}: --estimator picks a built-in network, and a spec names its own processes; "
                           "give one or the other")
    from tofnet.io.spec import load_spec
    loaded = load_spec(spec, allow_import=allow_import, replaced=replaced)
    network = loaded.network
    if not rotation and rotation_summary(network) is not None:
        raise NetworkError(f"{spec}: the spec connects an angular velocity process to its depth neurons (eq. 7); "
                           "remove it from the spec to compute eq. 8")
    if not undistort and network.of_type(UndistortProcess):
        raise NetworkError(f"{spec}: the spec undistorts (process '{network.of_type(UndistortProcess)[0].name}'); "
                           "remove it from the spec to keep raw pixels")
    if not undistort:
        ignore_lens(network)
    check_lens_once(network, recording, str(spec))
    if sensor_size is not None and network.sensor_size != tuple(sensor_size):
        resize(network, sensor_size)
    from tofnet.io.trust import cap_workers  # a spec may not ask for more workers than the machine has
    options = cap_workers(loaded.backend_options or {}, f"{spec}: backend")
    if loaded.backend is not None:
        _check_spec_backend(loaded, options)
    return network, dict(loaded.compile or {}), loaded.backend, options


def _check_spec_backend(loaded, options: dict) -> None:
    """A spec's backend options, checked as it is read: its file and line, not a bare message when it runs."""
    from tofnet.backends.registry import check_backend_options
    from tofnet.errors import BackendError, SpecError, located
    try:
        check_backend_options(loaded.backend, options)
    except BackendError as err:
        named = [key for key in options if repr(key) in str(err) or f"{key}:" in str(err)]
        line = loaded.backend_lines.get(named[0] if len(named) == 1 else "")
        raise SpecError(located(loaded.source, line, f"backend: {err}")) from None


def resize(network: Network, sensor_size: tuple[int, int]) -> None:
    """Give every process of ``network`` a new sensor size (px) and re-validate."""
    for process in network.processes:
        process.set_param("sensor_size", list(sensor_size))
    network.validate()


#: Command-line overrides: option name -> (process type(s), parameter).
OVERRIDES = {
    "timestep": ((InputProcess, TimeSurfaceProcess), "timestep"),
    "refractory": (InputProcess, "refractory"),
    "distance": (TimeOfTravelProcess, "distance"),
    "counter_bits": (TimeOfTravelProcess, "counter_bits"),
    "velocity_per": (VelocityProcess, "per"),
    "update_every": (VelocityProcess, "update_every"),
}


def apply_overrides(network: Network, **values: Any) -> None:
    """Set parameters by option name (see ``OVERRIDES``) or as ``PROCESS.PARAM`` (one process's parameter,
    converted and checked as a spec's: ``None`` clears an optional one); ``None`` values of the options are
    skipped (not given). The ``PROCESS.PARAM`` of one process are set together (``Process.set_params``: all
    or none, checked once), so their order does not matter."""
    together: dict[str, dict[str, Any]] = {}
    for option, value in values.items():
        process, dot, param = option.partition(".")
        if dot:
            together.setdefault(process, {})[param] = value
            continue
        if value is None:
            continue
        param, targets = override_targets(network, option)
        for process in targets:
            process.set_param(param, value)
    for process, params in together.items():
        network.process(process).set_params(params)
    network.validate()


def override_targets(network: Network, option: str) -> tuple[str, list]:
    """The parameter an option of ``OVERRIDES`` sets and the processes of ``network`` it sets it on;
    ``NetworkError`` for an unknown option or a network without such a process."""
    if option not in OVERRIDES:
        raise NetworkError(f"unknown override {option!r}; expected one of {', '.join(OVERRIDES)} "
                           f"or PROCESS.PARAM")
    classes, param = OVERRIDES[option]
    classes = classes if isinstance(classes, tuple) else (classes,)
    targets = [p for cls in classes for p in network.of_type(cls)]
    if not targets:
        raise NetworkError(f"--{option.replace('_', '-')}: the network has no "
                           f"{' or '.join(cls.__name__ for cls in classes)}")
    return param, targets


def run(recording: Recording, network: Network | None = None, *, backend: str = DEFAULT_BACKEND,
        estimator: str = DEFAULT_ESTIMATOR,
        backend_options: dict | None = None, compile_options: dict | None = None, record_tot: bool = False,
        probes: tuple[str, ...] | list[str] = (), monitors: list | tuple = (),
        progress: ProgressCallback | None = None) -> tuple[RunResult, Any]:
    """Compile ``network`` and run it on ``recording``.

    The default network is ``default_network(recording, estimator=estimator)``: the paper's
    (or, with ``estimator="improved"``, the time-surface estimator), sized to the recording,
    compensating the camera's rotation when the recording has rotation information.
    ``probes`` names output ports (``"process.port"``) to return besides the sinks. ``monitors`` (``tofnet.Monitor`` or ``"process.var@x,y"`` strings) are recorded
    while it runs, through a ``Session`` (model by model); ``result.extra["monitors"]``
    holds them. Returns ``(result, compiled)``.
    """
    from tofnet.backends.registry import get_backend
    from tofnet.compiler import compile_network

    if network is None:
        network = default_network(recording, estimator=estimator)
    compiled = compile_network(network, **(compile_options or {}))
    if monitors:
        from tofnet.session import Session
        with Session(compiled, recording, backend=backend, backend_options=backend_options, probes=probes,
                     record_tot=record_tot, monitors=monitors) as session:
            if progress is not None:  # model by model is slow: steps in pieces, the progress after each
                _run_in_pieces(session, progress)
            result = session.finish()
        result.extra["monitors"] = session.monitors
        return result, compiled
    result = get_backend(backend, **(backend_options or {})).run(compiled, recording, record_tot=record_tot,
                                                                 probes=probes, progress=progress)
    return result, compiled


def _run_in_pieces(session, progress: ProgressCallback) -> None:
    """Run a session on its recording to the step of the last event in pieces of about half a second
    (``tofnet.pacing``), calling ``progress(events fed, events)`` after each; ``finish`` runs the rest."""
    from tofnet.pacing import Pacer

    times = session.recording.events["t"]
    if not len(times):
        return
    pacer = Pacer(first=1, most=1 << 20)
    while True:
        before = session.step  # the last event's step as Session.run counts it (t0 is the stream's once fed)
        last = (int(times[-1]) - session.stream.t0_us) // session.timestep_us + 1
        if before >= last:
            return
        session.run(steps=pacer.size(last - before))
        pacer.took(session.step - before)
        progress(session.events_fed, len(times))


def constant_velocity(network: Network, text: str) -> None:
    """``--velocity TX,TY,TZ``: every velocity process sends this constant (m/s, camera frame)."""
    try:
        value = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise NetworkError(f"--velocity: expected TX,TY,TZ in m/s, got {text!r}") from None
    for process in network.of_type(VelocityProcess):
        process.set_param("velocity", value)
        process.set_param("source", "constant")


def run_source(source, network: Network, *, backend: str = DEFAULT_BACKEND, backend_options: dict | None = None,
               compile_options: dict | None = None, record_tot: bool = False, probes: tuple[str, ...] | list[str] = (),
               progress: ProgressCallback | None = None, spill_dir=None, spill_bytes: int = 256 << 20,
               chunk_events: int | None = None) -> tuple[RunResult, Any]:
    """Run ``network`` on an open recording (``tofnet.io.open_recording``), read in chunks.

    Events never sit in memory all at once (one chunk of ``chunk_events``, by default the
    backend's packet for a whole run: larger with workers, whose bands pay on large packets); with
    ``spill_dir`` an output goes to a temporary file there once it outgrows ``spill_bytes``, and
    comes back as a memory map. The result equals ``run`` on the whole recording. A backend
    without the ``stream`` capability is given the whole window read at once (``progress`` follows
    the reading; ``spill_dir`` and ``chunk_events`` do not apply).
    """
    from tofnet.backends.registry import get_backend
    from tofnet.backends.runtime import clock_of
    from tofnet.backends.stream import DEFAULT_PACKET_EVENTS, Collected
    from tofnet.compiler import compile_network

    known = source.metadata()
    compiled = compile_network(network, **(compile_options or {}))
    chosen = get_backend(backend, **(backend_options or {}))
    if "stream" not in chosen.capabilities:  # a backend that offers only ``run``: the whole window at once
        result = chosen.run(compiled, source.read(progress), record_tot=record_tot, probes=probes)
        return result, compiled
    stream = chosen.open_stream(compiled, recording=known, t0_us=clock_of(network).t0_us, probes=probes,
                                record_tot=record_tot)
    if chunk_events is None:
        chunk_events = getattr(chosen, "packet_events", DEFAULT_PACKET_EVENTS)
    collected = Collected(spill_dir, spill_bytes)
    # progress after the events are processed, not read: a chunk may take long on a slow backend, so with
    # progress asked each is fed in pieces of about half a second (tofnet.pacing: one chunk whole on a fast one)
    from tofnet.pacing import Pacer
    pacer = Pacer(first=1 << 12, most=chunk_events) if progress is not None else None
    try:
        read = 0
        chunks = iter(source.chunks(chunk_events))
        reading = getattr(stream, "clock", None)  # the file's decoding is not the network's time
        while True:
            with reading.reading() if reading is not None else nullcontext():
                chunk = next(chunks, None)
            if chunk is None:
                break
            if not read and hasattr(stream, "expect_packets"):  # bands for the chunks, not the pieces cut below
                stream.expect_packets(len(chunk))
            if pacer is None:
                collected.add(stream.feed_all(chunk))
                read += len(chunk)
                continue
            done = 0
            while done < len(chunk):
                piece = chunk[done:done + pacer.size(len(chunk) - done)]
                collected.add(stream.feed_all(piece))
                pacer.took(len(piece))
                done += len(piece)
                progress(read + done, source.n_events)
            read += len(chunk)
        if not read:
            from tofnet.errors import DataError, located
            raise DataError(located(source.path, None, "no events"))
        result = stream.close()
    except BaseException:
        stream.abort()
        raise
    collected.add(result.outputs)
    result.outputs = collected.joined(result.payloads, stream._empty)
    return result, compiled
