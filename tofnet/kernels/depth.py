"""The depth neuron's arithmetic (paper eq. 8), shared by every backend."""

from __future__ import annotations

from numba import njit

# Rejection reasons, in tofnet.backends.base.REJECT_REASONS order; EMITTED means kept.
EMITTED, NO_MEASUREMENT, TOO_NEAR, TOO_FAR = -1, 0, 1, 2


@njit(cache=True)
def signed_axis_count(m_positive: int, m_negative: int) -> int:
    """Signed counter of one axis: +m for motion towards +u/+v, -m towards -u/-v, 0 if unmeasured.

    Both directions fired: the smaller count wins (paper's heuristic); a tie is 0.
    """
    if m_positive > 0 and (m_negative == 0 or m_positive < m_negative):
        return m_positive
    if m_negative > 0 and (m_positive == 0 or m_negative < m_positive):
        return -m_negative
    return 0


@njit(cache=True)
def float_depth(signed_x: int, signed_y: int, at_x: float, at_y: float,
                seconds_per_count: float) -> float:
    """``Z = (A t)_x td_x + (A t)_y td_y`` metres, with ``td = signed count * dt / distance``."""
    return (at_x * signed_x + at_y * signed_y) * seconds_per_count


@njit(cache=True)
def classify(measured: bool, z: float, min_depth: float, max_depth: float) -> int:
    """EMITTED, or the reason the estimate is rejected (works for floats and fixed-point ints)."""
    if not measured:
        return NO_MEASUREMENT
    if z <= min_depth:
        return TOO_NEAR
    if z >= max_depth:
        return TOO_FAR
    return EMITTED
