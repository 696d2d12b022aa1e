"""Integer arithmetic of the depth path (the `fixed` backend); every rule is written out in docs/fixed_point.md.

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


# --- rotation (paper eq. 7; docs/rotation.md) ------------------------------------------------------------
#
# ``V = (B ω) * dt / distance`` (dimensionless per count) is quantised like ``W``, in the
# same format (F fractional bits, P-bit payload). The share ``r = 1 − s·V`` and the depth
# ``Z = N / r`` (``N = s·W``) are computed with integers only; the one division is exact
# and rounds half away from zero.


@njit(cache=True)
def fixed_share(signed_x: int, signed_y: int, v_x: int, v_y: int, frac_bits: int) -> int:
    """``r_raw = 2**F − s_x*V_x − s_y*V_y``: the translational share in units of ``2**-F`` (int64, not saturated).

    With counters of at most 30 bits and ``V`` of at most 32, ``|r_raw| < 2**62``.
    """
    return (1 << frac_bits) - signed_x * v_x - signed_y * v_y


@njit(cache=True)
def divide_round_half_away(numerator: int, denominator: int, shift: int, bits: int) -> int:
    """``numerator * 2**shift / denominator`` rounded half away from zero, saturated to ``bits`` bits.

    Exact for ``denominator > 0``, ``|numerator| < 2**63`` and ``shift <= 61``, ``bits <= 62``:
    the quotient of ``|numerator|`` is split into its whole part and ``shift`` bits of
    binary long division, and no intermediate value leaves int64 (``2 r >= d`` is tested
    as ``r >= d − r``). A ``denominator <= 0`` is outside the contract and gives the most
    negative value (so a caller's ``too_near`` test rejects it).
    """
    top = (1 << (bits - 1)) - 1
    if denominator <= 0:
        return -top - 1
    magnitude = -numerator if numerator < 0 else numerator
    whole = magnitude // denominator
    rest = magnitude - whole * denominator
    if whole > ((top + 1) >> shift):
        # The magnitude exceeds 2**(bits-1): saturated whichever the sign.
        return top if numerator >= 0 else -top - 1
    fraction = 0
    for _ in range(shift):
        fraction <<= 1
        if rest >= denominator - rest:
            rest -= denominator - rest
            fraction |= 1
        else:
            rest += rest
    if rest >= denominator - rest:  # the remainder is at least half a unit: away from zero
        fraction += 1
    magnitude = (whole << shift) + fraction
    if numerator >= 0:
        return magnitude if magnitude <= top else top
    return -magnitude if magnitude <= top + 1 else -top - 1


@njit(cache=True)
def fixed_depth_rotation(signed_x: int, signed_y: int, w_x: int, w_y: int, share_raw: int,
                         frac_bits: int, bits: int) -> int:
    """Eq. 7 on integers: ``Z_raw = round_half_away((s_x*W_x + s_y*W_y) * 2**F / r_raw)``, saturated to ``bits``.

    ``W`` and ``Z_raw`` in units of ``2**-F`` m, ``r_raw`` in units of ``2**-F``; the
    caller rejects ``r_raw <= min_share_raw`` (>= 0) first, so ``r_raw >= 1`` here.
    """
    return divide_round_half_away(signed_x * w_x + signed_y * w_y, share_raw, frac_bits, bits)


def rotation_depth_tolerance(m_x, m_y, z, share: float, frac_bits: int = DEFAULT_FRAC_BITS):
    """Bound on ``|z_fixed − z_float|`` (m) for eq. 7, without saturation.

    ``N`` and ``r`` are each off by at most ``c = (|m_x| + |m_y|) * 2**-(F+1)`` (rounded
    ``W`` and ``V``), the division adds half a unit: ``Z_q − Z = (εN − Z εr) / r_q + ρ``, so
    ``|Z_q − Z| <= c (1 + |z|) / share + 2**-(F+1)`` with ``share`` the fixed-point
    share ``r_raw * 2**-F`` and ``z`` the larger of the two depths (metres).
    """
    c = (abs(m_x) + abs(m_y)) * 2.0 ** -(frac_bits + 1)
    return c * (1.0 + abs(z)) / share + 2.0 ** -(frac_bits + 1)
