"""Parsing of physical quantities given as numbers or strings such as ``"1ms"``."""

from __future__ import annotations

import re

from tofnet.errors import TofnetError

_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
_LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_NUMBER_WITH_UNIT = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zµ]*)\s*$")


def _parse(value: object, units: dict[str, float], default_unit: str, what: str) -> float:
    if isinstance(value, bool):
        raise TofnetError(f"{what}: expected a number or a string like '1{default_unit}', got {value!r}")
    if isinstance(value, (int, float)):
        return float(value) * units[default_unit]
    if isinstance(value, str):
        match = _NUMBER_WITH_UNIT.match(value)
        if match:
            number, unit = match.groups()
            unit = unit or default_unit
            if unit in units:
                return float(number) * units[unit]
    names = ", ".join(units)
    raise TofnetError(f"{what}: expected a number or a string like '1{default_unit}' (units: {names}), got {value!r}")


def seconds(value: object, what: str = "duration") -> float:
    """A duration in seconds from ``0.001``, ``"1ms"``, ``"500us"`` or ``"0.5 s"``."""
    return _parse(value, _TIME_UNITS, "s", what)


def metres(value: object, what: str = "length") -> float:
    """A length in metres from ``0.5``, ``"50cm"`` or ``"500mm"``."""
    return _parse(value, _LENGTH_UNITS, "m", what)


def format_seconds(value: float) -> str:
    """Human-readable duration: ``0.001`` -> ``"1 ms"``."""
    magnitude = abs(value)
    if magnitude >= 1 or magnitude == 0:
        return f"{value:g} s"
    if magnitude >= 1e-3:
        return f"{value * 1e3:g} ms"
    return f"{value * 1e6:g} µs"
