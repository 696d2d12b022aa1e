"""One call from a recording to depth: load a network, compile it, run a backend."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tofnet.backends.base import ProgressCallback, RunResult
from tofnet.core.network import Network
from tofnet.errors import NetworkError
from tofnet.io.recording import Recording
from tofnet.networks import depth_network
from tofnet.processes import InputProcess, TimeOfTravelProcess, VelocityProcess

DEFAULT_BACKEND = "fixed"


def load_network(spec: str | Path | None = None, *, sensor_size: tuple[int, int] | None = None):
    """The network of a YAML spec (or the paper's default) and the spec's compile/backend settings.

    Returns ``(network, compile_options, backend_name_or_None, backend_options)``.
    ``sensor_size`` overrides the spec's (or the default 240x180).
    """
    if spec is None:
        network = depth_network(sensor_size or (240, 180))
        return network, {}, None, {}
    from tofnet.io.spec import load_spec
    loaded = load_spec(spec)
    network = loaded.network
    if sensor_size is not None and network.sensor_size != tuple(sensor_size):
        resize(network, sensor_size)
    return network, dict(loaded.compile or {}), loaded.backend, dict(loaded.backend_options or {})


def resize(network: Network, sensor_size: tuple[int, int]) -> None:
    """Give every process of ``network`` a new sensor size (px) and re-validate."""
    for process in network.processes:
        process.set_param("sensor_size", list(sensor_size))
    network.validate()


#: Command-line overrides: option name -> (process type, parameter).
OVERRIDES = {
    "timestep": (InputProcess, "timestep"),
    "refractory": (InputProcess, "refractory"),
    "distance": (TimeOfTravelProcess, "distance"),
    "counter_bits": (TimeOfTravelProcess, "counter_bits"),
    "velocity_per": (VelocityProcess, "per"),
    "update_every": (VelocityProcess, "update_every"),
}


def apply_overrides(network: Network, **values: Any) -> None:
    """Set parameters by option name (see ``OVERRIDES``); ``None`` values are skipped."""
    for option, value in values.items():
        if value is None:
            continue
        if option not in OVERRIDES:
            raise NetworkError(f"unknown override {option!r}; expected one of {', '.join(OVERRIDES)}")
        cls, param = OVERRIDES[option]
        targets = network.of_type(cls)
        if not targets:
            raise NetworkError(f"--{option.replace('_', '-')}: the network has no {cls.__name__}")
        for process in targets:
            process.set_param(param, value)
    network.validate()


def run(recording: Recording, network: Network | None = None, *, backend: str = DEFAULT_BACKEND,
        backend_options: dict | None = None, compile_options: dict | None = None, record_tot: bool = False,
        probes: tuple[str, ...] | list[str] = (), monitors: list | tuple = (),
        progress: ProgressCallback | None = None) -> tuple[RunResult, Any]:
    """Compile ``network`` (default: the paper's, sized to the recording) and run it on ``recording``.

    ``probes`` names output ports (``"process.port"``) to return besides the sinks.
    ``monitors`` (``tofnet.Monitor`` or ``"process.var@x,y"`` strings) are recorded while it runs,
    through a ``Session`` (model by model); ``result.extra["monitors"]`` holds them.
    Returns ``(result, compiled)``.
    """
    from tofnet.backends.registry import get_backend
    from tofnet.compiler import compile_network

    if network is None:
        network = depth_network(recording.sensor_size or (240, 180))
    compiled = compile_network(network, **(compile_options or {}))
    if monitors:
        from tofnet.session import Session
        with Session(compiled, recording, backend=backend, backend_options=backend_options, probes=probes,
                     record_tot=record_tot, monitors=monitors) as session:
            result = session.finish()
        result.extra["monitors"] = session.monitors
        return result, compiled
    result = get_backend(backend, **(backend_options or {})).run(compiled, recording, record_tot=record_tot,
                                                                 probes=probes, progress=progress)
    return result, compiled


def constant_velocity(network: Network, text: str) -> None:
    """``--velocity TX,TY,TZ``: every velocity process sends this constant (m/s, camera frame)."""
    try:
        value = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise NetworkError(f"--velocity: expected TX,TY,TZ in m/s, got {text!r}") from None
    for process in network.of_type(VelocityProcess):
        process.set_param("velocity", value)
        process.set_param("source", "constant")
