"""State variables a process declares (Lava's ``Var``): what a backend lets you read and set between runs."""

from __future__ import annotations

from dataclasses import dataclass

#: Shapes a variable may have: per pixel ``(height, width)``, per pixel and channel
#: ``(channels, height, width)``, or a few numbers for the whole process.
SHAPES = ("pixel", "channels", "vector")


@dataclass(frozen=True)
class Var:
    """One state variable of a process.

    ``shape``: ``"pixel"`` -> ``(height, width)``, ``"channels"`` -> ``(channels, height,
    width)``, ``"vector"`` -> ``(channels,)``. ``dtype`` is the same on every backend
    (a backend storing the state another way converts: e.g. the event-driven units keep
    facilitation timestamps and report the counter a unit would show). Values are read at
    a step boundary: the state at the start of the session's current step. ``settable``:
    whether ``Session.set`` may change it between runs.
    """

    name: str
    shape: str
    dtype: str
    unit: str = ""
    doc: str = ""
    channels: int = 1
    settable: bool = False

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"Var {self.name!r}: shape must be one of {SHAPES}, got {self.shape!r}")

    def shape_for(self, sensor_size: tuple[int, int]) -> tuple[int, ...]:
        """The array shape on a sensor of ``(width, height)`` pixels."""
        width, height = sensor_size
        if self.shape == "pixel":
            return (height, width)
        if self.shape == "channels":
            return (self.channels, height, width)
        return (self.channels,)
