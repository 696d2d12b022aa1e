"""Typed, documented process parameters with units and checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from tofnet.errors import NetworkError, TofnetError
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

    def coerce(self, value: Any, owner: str) -> Any:
        """Return ``value`` converted to this parameter's kind, or raise naming the field."""
        field = f"{owner}.{self.name}"
        if value is None:
            if self.optional:
                return None
            raise NetworkError(f"{field}: a value is required ({self.doc})")
        try:
            out = _CONVERTERS[self.kind](value, field)
        except TofnetError as err:
            raise NetworkError(str(err)) from None
        if self.choices and out not in self.choices:
            raise NetworkError(f"{field}: expected one of {', '.join(map(str, self.choices))}, got {value!r}")
        for number in (out if isinstance(out, tuple) else (out,)):
            if isinstance(number, (int, float)) and not isinstance(number, bool):
                if self.minimum is not None and number < self.minimum:
                    raise NetworkError(f"{field}: expected at least {self.minimum:g}{self.unit and ' ' + self.unit}, got {value!r}")
                if self.maximum is not None and number > self.maximum:
                    raise NetworkError(f"{field}: expected at most {self.maximum:g}{self.unit and ' ' + self.unit}, got {value!r}")
        return out


def _integer(value: Any, field: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or int(value) != value:
        raise TofnetError(f"{field}: expected a whole number, got {value!r}")
    return int(value)


def _number(value: Any, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TofnetError(f"{field}: expected a number, got {value!r}")
    return float(value)


def _boolean(value: Any, field: str) -> bool:
    if not isinstance(value, bool):
        raise TofnetError(f"{field}: expected true or false, got {value!r}")
    return value


def _string(value: Any, field: str) -> str:
    if not isinstance(value, str):
        raise TofnetError(f"{field}: expected a string, got {value!r}")
    return value


def parse_size(value: Any, field: str) -> tuple[int, int]:
    if isinstance(value, str) and "x" in value:
        value = value.split("x")
        try:
            value = [int(v) for v in value]
        except ValueError:
            raise TofnetError(f"{field}: expected WIDTHxHEIGHT in pixels, got {value!r}") from None
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise TofnetError(f"{field}: expected [width, height] in pixels, got {value!r}")
    width, height = (_integer(v, field) for v in value)
    if width < 1 or height < 1:
        raise TofnetError(f"{field}: width and height must be positive, got {value!r}")
    return (width, height)


def _floats(value: Any, field: str) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)):
        raise TofnetError(f"{field}: expected a list of numbers, got {value!r}")
    return tuple(_number(v, field) for v in value)


def _vector3(value: Any, field: str) -> tuple[float, float, float]:
    out = _floats(value, field)
    if len(out) != 3:
        raise TofnetError(f"{field}: expected three numbers [x, y, z], got {value!r}")
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
