"""State variables a process declares (Lava's ``Var``): what a backend lets you read and set between runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
    #: The values ``Session.set`` accepts, in ``unit`` (None: what ``dtype`` holds).
    low: int | None = None
    high: int | None = None

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

    def check(self, value, sensor_size: tuple[int, int]) -> np.ndarray:
        """``value`` (broadcast to the variable's shape) as a new array of its dtype; ``ValueError``
        (one line: what it can hold) for other shapes, non-numbers, NaN/inf, fractions of an
        integer variable or values outside ``low .. high``, checked before any conversion."""
        expected = self.shape_for(sensor_size)
        dtype = np.dtype(self.dtype)
        try:
            array = np.asarray(value)
        except (ValueError, TypeError, OverflowError):
            array = np.asarray(None)
        if array.dtype.kind not in "biuf":
            raise ValueError(f"expected numbers ({self.dtype}), got {type(value).__name__} of {array.dtype}")
        try:
            array = np.broadcast_to(array, expected)
        except ValueError:
            raise ValueError(f"expected an array broadcastable to {expected}, got shape {array.shape}") from None
        if array.dtype.kind == "f" and not np.isfinite(array).all():
            raise ValueError(f"expected finite values ({self.dtype}), got NaN or inf")
        if array.dtype.kind == "f" and dtype.kind in "iu" and (array != np.floor(array)).any():
            raise ValueError(f"expected whole numbers ({self.dtype}), got fractions")
        limits = np.iinfo(dtype) if dtype.kind in "iu" else np.finfo(dtype)
        low = limits.min if self.low is None else self.low
        high = limits.max if self.high is None else self.high
        if array.size:
            least, most = array.min(), array.max()
            # floats compared as floats: 2.0**63 must not pass as int64's 2**63 - 1
            outside = (float(least) < low or float(most) > high) if array.dtype.kind == "f" else \
                (int(least) < low or int(most) > high)
            if outside:
                raise ValueError(f"values must be in {low} .. {high} {self.unit}".rstrip() +
                                 f", got {least} .. {most}")
        return np.array(array, dtype=dtype)
