"""Ports: the typed endpoints through which processes exchange spikes."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

from tofnet.errors import NetworkError

if TYPE_CHECKING:
    from tofnet.core.process import Process


class Payload(str, Enum):
    """What a graded spike on a port carries."""

    POLARITY = "polarity"  # input events: 1 = ON, 0 = OFF
    COUNT = "count"  # time-of-travel counters, steps
    VELOCITY_TERM = "velocity_term"  # A t, px*m/s
    DEPTH = "depth"  # metres


@dataclass(frozen=True)
class PortSpec:
    """Declaration of a port: its name, payload and channels per pixel."""

    name: str
    payload: Payload
    channels: int = 1
    doc: str = ""
    required: bool = True


class Port:
    """A port of one process instance; its shape is ``(channels, height, width)``."""

    def __init__(self, process: "Process", spec: PortSpec):
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
        return f"<{type(self).__name__} {self.qualified_name} {self.spec.payload.value}>"


class OutPort(Port):
    """Sends spikes; may fan out to any number of input ports."""

    def __init__(self, process: "Process", spec: PortSpec):
        super().__init__(process, spec)
        self.targets: list[InPort] = []

    def connect(self, target: "InPort") -> None:
        """Connect this output to ``target``; spikes sent in step k arrive in step k+1."""
        if isinstance(target, OutPort):
            raise NetworkError(f"cannot connect output {self.qualified_name} to output {target.qualified_name}: "
                               "connect an output port to an input port")
        if not isinstance(target, InPort):
            raise NetworkError(f"{self.qualified_name}.connect: expected an input port, got {target!r}")
        if target.source is not None:
            raise NetworkError(f"{target.qualified_name} is already connected to {target.source.qualified_name}; "
                               "an input port takes one source")
        if target.spec.payload != self.spec.payload:
            raise NetworkError(f"cannot connect {self.qualified_name} ({self.spec.payload.value}) to "
                               f"{target.qualified_name}, which expects {target.spec.payload.value}")
        target.source = self
        self.targets.append(target)


class InPort(Port):
    """Receives spikes from exactly one output port."""

    def __init__(self, process: "Process", spec: PortSpec):
        super().__init__(process, spec)
        self.source: OutPort | None = None

    def connect(self, target: "Port") -> None:
        raise NetworkError(f"cannot connect from input {self.qualified_name}: connect an output port to it "
                           f"(out_port.connect({self.qualified_name})) or use connect_from")

    def connect_from(self, source: OutPort) -> None:
        """Connect ``source`` to this input."""
        if not isinstance(source, OutPort):
            raise NetworkError(f"{self.qualified_name}.connect_from: expected an output port, got {source!r}")
        source.connect(self)
