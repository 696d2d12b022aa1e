"""Integer arithmetic of the depth path (DESIGN §2); every rule is written out in docs/fixed_point.md.

A quantity ``q`` in a format with ``F`` fractional bits and a ``P``-bit signed payload
is stored as the integer ``raw = saturate(round_half_away(q * 2**F), P)``, i.e. in
units of ``2**-F``, two's-complement range ``[-2**(P-1), 2**(P-1) - 1]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from numba import njit

from tofnet.errors import BackendError

#: Defaults: 16 fractional bits (1/65536 m ~ 15 µm), 24-bit graded-spike payload (Lava's
#: fixed-point models carry graded spikes as int32 with ``precision=24``).
DEFAULT_FRAC_BITS = 16
DEFAULT_PAYLOAD_BITS = 24
#: Widest payload accepted: counter (<= 30 bits) x payload must fit the int64 accumulator.
MAX_PAYLOAD_BITS = 32


@njit(cache=True)
def saturate(value: int, bits: int) -> int:
    """Clamp an integer to the signed two's-complement range of ``bits`` bits."""
    top = (1 << (bits - 1)) - 1
    if value > top:
        return top
    if value < -top - 1:
        return -top - 1
    return value


@njit(cache=True)
def round_half_away(value: float) -> int:
    """Nearest integer, halves away from zero (2.5 -> 3, -2.5 -> -3).

    ``floor(|v| + 0.5)`` would round 0.49999999999999994 up (the sum rounds to 1.0),
    so the fraction is compared instead; ``|v| - floor(|v|)`` is exact.
    """
    magnitude = abs(value)
    whole = math.floor(magnitude)
    if magnitude - whole >= 0.5:
        whole += 1.0
    result = int(whole)
    return result if value >= 0 else -result


@njit(cache=True)
def quantize(value: float, frac_bits: int, bits: int) -> int:
    """``value`` as a fixed-point integer: round half away from zero, then saturate to ``bits``."""
    scaled = value * (1 << frac_bits)  # exact: a power of two
    if scaled != scaled:  # NaN: no meaningful value; inputs are checked finite upstream
        return 0
    limit = float(1 << bits)  # beyond any payload: saturate before the int conversion overflows
    if scaled >= limit:
        return saturate(1 << bits, bits)
    if scaled <= -limit:
        return saturate(-(1 << bits), bits)
    return saturate(round_half_away(scaled), bits)


@njit(cache=True)
def fixed_depth(signed_x: int, signed_y: int, w_x: int, w_y: int, bits: int) -> int:
    """``Z_raw = s_x*W_x + s_y*W_y`` in an int64 accumulator, saturated to the ``bits``-bit payload.

    ``W`` is metres per count (``A t * dt / distance``) in the fixed-point format, so
    ``Z_raw`` is in the same format (units of ``2**-F`` m).
    """
    return saturate(signed_x * w_x + signed_y * w_y, bits)


@dataclass(frozen=True)
class FixedPointFormat:
    """Fractional bits ``F`` and signed payload width ``P`` of ``W``, ``Z`` and the depth thresholds."""

    frac_bits: int = DEFAULT_FRAC_BITS
    payload_bits: int = DEFAULT_PAYLOAD_BITS

    def __post_init__(self) -> None:
        if not 2 <= self.payload_bits <= MAX_PAYLOAD_BITS:
            raise BackendError(f"payload_bits must be in [2, {MAX_PAYLOAD_BITS}], got {self.payload_bits}")
        if not 0 <= self.frac_bits < self.payload_bits:
            raise BackendError(f"frac_bits must be in [0, payload_bits), got {self.frac_bits} "
                               f"(payload_bits={self.payload_bits})")

    @property
    def lsb(self) -> float:
        """Value of one unit of ``raw``: ``2**-F`` (metres for Z, metres per count for W)."""
        return 2.0 ** -self.frac_bits

    @property
    def max_raw(self) -> int:
        return (1 << (self.payload_bits - 1)) - 1

    @property
    def min_raw(self) -> int:
        return -(1 << (self.payload_bits - 1))

    @property
    def max_value(self) -> float:
        """Largest representable value, e.g. 127.99998 m for F = 16, P = 24."""
        return self.max_raw * self.lsb

    def quantize(self, value: float) -> int:
        return int(quantize(float(value), self.frac_bits, self.payload_bits))

    def to_float(self, raw):
        """``raw * 2**-F`` (exact in float64 for payloads up to 53 bits)."""
        return raw * self.lsb


def depth_tolerance(m_x, m_y, frac_bits: int = DEFAULT_FRAC_BITS):
    """Bound on ``|z_fixed - z_float|`` in metres without saturation: ``(|m_x| + |m_y|) * 2**-(F+1)``.

    Each ``W`` is off by at most half a unit (rounding); ``Z_raw`` is exact, so the error is
    at most the count-weighted sum of the two rounding errors.
    """
    return (abs(m_x) + abs(m_y)) * 2.0 ** -(frac_bits + 1)


def relative_error_bound(at: float, timestep: float, distance: int, frac_bits: int = DEFAULT_FRAC_BITS) -> float:
    """Worst relative depth change from quantising ``W = |A t| * dt / distance`` (single measured axis).

    ``Z = m W`` with an integer count ``m``, so the relative error is that of ``W``:
    ``2**-(F+1) / W``, independent of the depth.
    """
    w = abs(at) * timestep / distance
    return 2.0 ** -(frac_bits + 1) / w
