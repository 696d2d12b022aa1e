"""Typed, documented process parameters with units and checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import math

from tofnet.errors import NetworkError, TofnetError, quote
from tofnet.events import sensor_size_problem
from tofnet.units import seconds, metres

#: Parameter kinds: how a raw value (Python or YAML) becomes the stored value.
KINDS = ("int", "float", "bool", "str", "duration", "length", "size", "vector3", "floats")


@dataclass(frozen=True)
class Param:
    """One parameter of a process.

    ``kind`` is one of ``KINDS``; ``duration`` values are stored in seconds and
    ``length`` values in metres; ``size`` is ``(width, height)`` in pixels;
    ``vector3`` three floats; ``floats`` any number of floats.
    """

    name: str
    kind: str
    default: Any
    unit: str = ""
    doc: str = ""
    choices: tuple = ()
    minimum: float | None = None
    maximum: float | None = None
    optional: bool = False  # None is an accepted value
    reads_file: bool = False  # the value names a file the process reads (protected from outputs)
    selects_code: bool = False  # a number that picks another compiled kernel (``tofnet warmup`` runs each)

    def coerce(self, value: Any, owner: str) -> Any:
        """Return ``value`` converted to this parameter's kind, or raise naming the field."""
        field = f"{owner}.{self.name}"
        if value is None:
            if self.optional:
                return None
            raise NetworkError(f"{field}: a value is required ({self.doc})")
        try:
            if self.kind == "duration" and self.maximum is not None:
                out = seconds(value, field, limit=self.maximum)
            else:
                out = _CONVERTERS[self.kind](value, field)
        except TofnetError as err:
            raise NetworkError(str(err)) from None
        if self.choices and out not in self.choices:
            raise NetworkError(f"{field}: expected one of {', '.join(map(str, self.choices))}, got {quote(value)}")
        for number in (out if isinstance(out, tuple) else (out,)):
            if isinstance(number, (int, float)) and not isinstance(number, bool):
                if self.minimum is not None and number < self.minimum:
                    raise NetworkError(f"{field}: expected at least {self.minimum:g}{self.unit and ' ' + self.unit}, got {quote(value)}")
                if self.maximum is not None and number > self.maximum:
                    raise NetworkError(f"{field}: expected at most {self.maximum:g}{self.unit and ' ' + self.unit}, "
                                       f"got {quote(value)}")
        return out


def _integer(value: Any, field: str) -> int:
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or (isinstance(value, float) and not math.isfinite(value)) or int(value) != value):
        raise TofnetError(f"{field}: expected a whole number, got {quote(value)}")
    return int(value)


def _number(value: Any, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TofnetError(f"{field}: expected a number, got {quote(value)}")
    try:
        out = float(value)
    except OverflowError:
        out = math.inf
    if not math.isfinite(out):
        raise TofnetError(f"{field}: expected a finite number, got {quote(value)}")
    return out


def _boolean(value: Any, field: str) -> bool:
    if not isinstance(value, bool):
        raise TofnetError(f"{field}: expected true or false, got {quote(value)}")
    return value


def _string(value: Any, field: str) -> str:
    if not isinstance(value, str):
        raise TofnetError(f"{field}: expected a string, got {quote(value)}")
    return value


def parse_size(value: Any, field: str) -> tuple[int, int]:
    """``"640x480"`` or ``[640, 480]`` -> ``(width, height)`` px, within the documented
    limits (``tofnet.events.MAX_SENSOR_SIDE``, ``MAX_SENSOR_PIXELS``)."""
    if isinstance(value, str) and "x" in value and len(value) <= 40:
        parts = value.split("x")
        try:
            value = [int(v) for v in parts]
        except ValueError:
            raise TofnetError(f"{field}: expected WIDTHxHEIGHT in pixels, got {quote(value)}") from None
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise TofnetError(f"{field}: expected [width, height] in pixels, got {quote(value)}")
    width, height = (_integer(v, field) for v in value)
    problem = sensor_size_problem(width, height)
    if problem:
        raise TofnetError(f"{field}: {problem}")
    return (width, height)


def _floats(value: Any, field: str) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)):
        raise TofnetError(f"{field}: expected a list of numbers, got {quote(value)}")
    return tuple(_number(v, field) for v in value)


def _vector3(value: Any, field: str) -> tuple[float, float, float]:
    out = _floats(value, field)
    if len(out) != 3:
        raise TofnetError(f"{field}: expected three numbers [x, y, z], got {quote(value)}")
    return out  # type: ignore[return-value]


_CONVERTERS: dict[str, Callable[[Any, str], Any]] = {
    "int": _integer,
    "float": _number,
    "bool": _boolean,
    "str": _string,
    "duration": lambda v, f: seconds(v, f),
    "length": lambda v, f: metres(v, f),
    "size": parse_size,
    "vector3": _vector3,
    "floats": _floats,
}
