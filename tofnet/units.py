"""Parsing of physical quantities given as numbers or strings such as ``"1ms"``."""

from __future__ import annotations

import math
import re

from tofnet.errors import DataError, TofnetError, quote
from tofnet.events import MAX_TIME_US

#: Largest magnitude of any duration, in seconds: the documented time range (2**61 µs).
MAX_DURATION_S = MAX_TIME_US * 1e-6

#: Longest timestep and refractory period (s): an hour is far beyond any use and keeps
#: step arithmetic well inside int64 microseconds (docs/reliability.md). A depth file's too.
MAX_PERIOD_S = 3600.0
#: Most windows ``eval`` scores and ``plot error`` draws (about 1 KB of memory each in ``eval``): 2.8 h of
#: eval's default 100 ms windows; a figure is narrower than that anyway.
MAX_METRIC_WINDOWS = 100_000
#: Most depth maps ``export --maps`` writes (2-3 sensor-sized files each): an hour of 10 ms maps is 360,000.
MAX_MAPS = 1_000_000

_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
_LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_NUMBER_WITH_UNIT = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zµ]*)\s*$")


def microseconds(seconds: float) -> int:
    """``seconds`` as whole microseconds (events are stamped in µs): the one conversion."""
    return int(round(seconds * 1e6))


def seconds_of(us: int) -> float:
    """``us`` microseconds as seconds, ``us / 1e6``: the one conversion back (models, fused path, results)."""
    return us / 1e6


def _parse(value: object, units: dict[str, float], default_unit: str, what: str) -> float:
    """A finite number in the base unit; NaN, infinities and overflowing values are refused."""
    if isinstance(value, bool):
        raise TofnetError(f"{what}: expected a number or a string like '1{default_unit}', got {quote(value)}")
    number, scale = None, units[default_unit]
    if isinstance(value, (int, float)):
        number = value
    elif isinstance(value, str) and len(value) <= 100:
        match = _NUMBER_WITH_UNIT.match(value)
        if match and (match.group(2) or default_unit) in units:
            number, scale = match.group(1), units[match.group(2) or default_unit]
    if number is None:
        names = ", ".join(units)
        raise TofnetError(f"{what}: expected a number or a string like '1{default_unit}' (units: {names}), "
                          f"got {quote(value)}")
    try:
        out = float(number) * scale
    except OverflowError:
        out = math.inf
    if not math.isfinite(out):
        raise TofnetError(f"{what}: expected a finite number, got {quote(value)}")
    return out


def seconds(value: object, what: str = "duration", limit: float = MAX_DURATION_S) -> float:
    """A duration in seconds from ``0.001``, ``"1ms"``, ``"500us"`` or ``"0.5 s"``.

    Finite and ``|value| <= limit`` (default: within the documented time range, 2**61 µs).
    """
    out = _parse(value, _TIME_UNITS, "s", what)
    if abs(out) > min(limit, MAX_DURATION_S * (1 - 1e-15)):
        raise TofnetError(f"{what}: expected at most {min(limit, MAX_DURATION_S):.6g} s in magnitude, "
                          f"got {quote(value)}")
    return out


def metres(value: object, what: str = "length") -> float:
    """A finite length in metres from ``0.5``, ``"50cm"`` or ``"500mm"``."""
    return _parse(value, _LENGTH_UNITS, "m", what)


def format_seconds(value: float) -> str:
    """Human-readable duration: ``0.001`` -> ``"1 ms"``."""
    magnitude = abs(value)
    if magnitude >= 1 or magnitude == 0:
        return f"{value:g} s"
    if magnitude >= 1e-3:
        return f"{value * 1e3:g} ms"
    return f"{value * 1e6:g} µs"


def format_bytes(n: int) -> str:
    """``7_950_000_000`` -> ``"7.95 GB"`` (decimal units, three significant digits)."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(n) >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


def format_steps(n: int) -> str:
    """``"1 step"``, ``"2 steps"``."""
    return f"{n} step" if n == 1 else f"{n} steps"


def bounded_windows(count: int, window_us: int, what: str, fix: str, most: int, unit: str = "windows") -> int:
    """``count`` windows of ``window_us`` when at most ``most``, else a one-line ``DataError``: ``what`` makes them
    (a depth file's time span, which may be hostile), ``fix`` what would narrow them. Counted with Python ints, and
    checked before anything is allocated per window (a 2**61 µs span in 1 ms windows is 2.3e15 of them)."""
    if count > most:
        raise DataError(f"{what} make {count:,} {unit} of {format_seconds(window_us * 1e-6)}, more than the "
                        f"{most:,} allowed; {fix}")
    return count
