"""Ports: the typed endpoints through which processes exchange spikes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from tofnet.errors import NetworkError
from tofnet.events import DEPTH_DTYPE, TOT_DTYPE

#: Fields every record of a port carries: the step it was sent in, and for spikes its pixel.
STEP_FIELD = ("step", "<i8")
PIXEL_FIELDS = (("x", "<u2"), ("y", "<u2"))


@dataclass(frozen=True)
class Payload:
    """What a port carries, and how one message is laid out in memory.

    ``kind == "spikes"``: graded spikes of single pixels; a record has ``step`` (the step it
    was sent in), ``x``, ``y`` (pixels) and the payload's own fields. ``kind == "field"``: a
    value defined over the whole image, sent now and then as one record of coefficients
    (``step`` and the fields); how the value at a pixel follows from them is the payload's
    documented meaning (e.g. ``velocity_term``). Two ports connect when their payload names
    match. Users define their own: ``Payload("gain", (("g", "<f8"),), doc="...")``.
    """

    name: str
    fields: tuple[tuple[str, str], ...] = ()
    doc: str = ""
    kind: str = "spikes"
    #: Full record dtype when it is not ``step, x, y`` + fields (the built-in depth layout).
    layout: tuple[tuple[str, str], ...] | None = None

    POLARITY: ClassVar["Payload"]
    COUNT: ClassVar["Payload"]
    VELOCITY_TERM: ClassVar["Payload"]
    ROTATION_TERM: ClassVar["Payload"]
    DEPTH: ClassVar["Payload"]

    def __post_init__(self) -> None:
        if self.kind not in ("spikes", "field"):
            raise NetworkError(f"payload {self.name!r}: kind must be 'spikes' or 'field', got {self.kind!r}")
        names = self.dtype.names
        needed = ("step", "x", "y") if self.kind == "spikes" else ("step",)
        missing = [n for n in needed if n not in names]
        if missing:
            raise NetworkError(f"payload {self.name!r}: its records lack {', '.join(missing)}")

    @property
    def value(self) -> str:
        """The payload's name (what errors and docs print)."""
        return self.name

    @property
    def dtype(self) -> np.dtype:
        """The record layout of one spike (or field update) on a port of this payload."""
        if self.layout is not None:
            return np.dtype(list(self.layout))
        base = [STEP_FIELD] + (list(PIXEL_FIELDS) if self.kind == "spikes" else [])
        return np.dtype(base + list(self.fields))

    def empty(self) -> np.ndarray:
        return np.empty(0, dtype=self.dtype)


def _layout(dtype: np.dtype) -> tuple[tuple[str, str], ...]:
    return tuple((name, dtype.fields[name][0].str) for name in dtype.names)


Payload.POLARITY = Payload("polarity", (("p", "u1"),), "one spike per active pixel: 1 = ON, 0 = OFF")
Payload.COUNT = Payload("count", doc="time-of-travel counters: direction (0-3: +u, -u, +v, -v), count in steps",
                        layout=_layout(TOT_DTYPE))
Payload.VELOCITY_TERM = Payload(
    "velocity_term", (("tx", "<f8"), ("ty", "<f8"), ("tz", "<f8")),
    "A t (px*m/s): each update carries the camera velocity t (m/s, camera frame); the value at a pixel is "
    "A(u, v) t evaluated where the sender's sampling says (per pixel or at patch centres)", kind="field")
Payload.ROTATION_TERM = Payload(
    "rotation_term", (("wx", "<f8"), ("wy", "<f8"), ("wz", "<f8")),
    "B ω (px/s): each update carries the camera's angular velocity ω (rad/s, camera frame); the value at a "
    "pixel is the rotational flow B(u, v) ω at that pixel (paper eq. 7)", kind="field")
Payload.DEPTH = Payload("depth", doc="depth estimates: z metres, t = end of the step in µs", layout=_layout(DEPTH_DTYPE))


@dataclass(frozen=True)
class PortSpec:
    """Declaration of a port: name, payload, channels per pixel; for inputs whether it
    must be connected (``required``) and whether several outputs may feed it (``fan_in``); for
    outputs the steps the process adds before sending on it, beyond the one step of each
    connection (``added_latency_steps``; None: the process's ``added_latency_steps``)."""

    name: str
    payload: Payload
    channels: int = 1
    doc: str = ""
    required: bool = True
    fan_in: bool = False
    added_latency_steps: int | None = None


class PortOwner(Protocol):
    """What a port reads of the process it belongs to (a ``tofnet.core.process.Process``, which
    imports this module: the protocol keeps the import one way)."""

    name: str

    @property
    def sensor_size(self) -> tuple[int, int] | None: ...

    @classmethod
    def port_latency_steps(cls, port: str) -> int: ...


class Port:
    """A port of one process instance; its shape is ``(channels, height, width)``."""

    def __init__(self, process: PortOwner, spec: PortSpec):
        self.process = process
        self.spec = spec

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def qualified_name(self) -> str:
        """``process.port``, the name used in errors and YAML specs."""
        return f"{self.process.name}.{self.spec.name}"

    @property
    def shape(self) -> tuple[int, int, int] | None:
        size = self.process.sensor_size
        if size is None:
            return None
        return (self.spec.channels, size[1], size[0])

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.qualified_name} {self.spec.payload.name}>"


class OutPort(Port):
    """Sends spikes; may fan out to any number of input ports."""

    def __init__(self, process: PortOwner, spec: PortSpec):
        super().__init__(process, spec)
        self.targets: list[InPort] = []

    @property
    def added_latency_steps(self) -> int:
        """Steps the process adds before sending here (``Process.port_latency_steps``)."""
        return type(self.process).port_latency_steps(self.spec.name)

    def connect(self, target: "InPort") -> None:
        """Connect this output to ``target``; spikes sent in step k arrive in step k+1."""
        if isinstance(target, OutPort):
            raise NetworkError(f"cannot connect output {self.qualified_name} to output {target.qualified_name}: "
                               "connect an output port to an input port")
        if not isinstance(target, InPort):
            raise NetworkError(f"{self.qualified_name}.connect: expected an input port, got {target!r}")
        if self in target.sources:
            raise NetworkError(f"{self.qualified_name} is already connected to {target.qualified_name}")
        if target.sources and not target.spec.fan_in:
            raise NetworkError(f"{target.qualified_name} is already connected to {target.sources[0].qualified_name}; "
                               "this input port takes one source")
        if target.spec.payload.name != self.spec.payload.name:
            raise NetworkError(f"cannot connect {self.qualified_name} ({self.spec.payload.name}) to "
                               f"{target.qualified_name}, which expects {target.spec.payload.name}")
        target.sources.append(self)
        self.targets.append(target)


class InPort(Port):
    """Receives spikes from one output port (several when its spec allows ``fan_in``)."""

    def __init__(self, process: PortOwner, spec: PortSpec):
        super().__init__(process, spec)
        self.sources: list[OutPort] = []

    @property
    def source(self) -> OutPort | None:
        """The (first) output feeding this port, None when unconnected."""
        return self.sources[0] if self.sources else None

    def connect(self, target: "Port") -> None:
        raise NetworkError(f"cannot connect from input {self.qualified_name}: connect an output port to it "
                           f"(out_port.connect({self.qualified_name})) or use connect_from")

    def connect_from(self, source: OutPort) -> None:
        """Connect ``source`` to this input."""
        if not isinstance(source, OutPort):
            raise NetworkError(f"{self.qualified_name}.connect_from: expected an output port, got {source!r}")
        source.connect(self)
