"""The depth neuron's arithmetic (paper eq. 8, and eq. 7 for a rotating camera), shared by every backend."""

from __future__ import annotations

import math

from numba import njit

# Rejection codes, in the order of the rejection reasons ``DepthProcess.counters`` declares; EMITTED means kept.
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


# --- rotation (paper eq. 7; docs/rotation.md) ------------------------------------------------------------

#: Rejected because translation explains too small a share of the measured image motion
#: (``translational_share <= min_share``): ``"rotation_dominated"`` in REJECT_REASONS.
ROTATION_DOMINATED = 3


@njit(cache=True)
def translational_share(signed_x: int, signed_y: int, bw_x: float, bw_y: float,
                        seconds_per_count: float) -> float:
    """``r = 1 − (B ω)·td``: the share of the measured image motion that translation explains.

    ``(A t / Z + B ω)·td = 1`` for an edge crossing a pixel in ``td``, so
    ``(A t / Z)·td = r``; ``r = 1`` without rotation. A relative error ``e`` of ``td``
    becomes a depth error of about ``e / r``. ``bw`` in px/s, ``td = signed count *
    seconds_per_count``; dimensionless.
    """
    return 1.0 - (bw_x * signed_x + bw_y * signed_y) * seconds_per_count


@njit(cache=True)
def float_depth_rotation(signed_x: int, signed_y: int, at_x: float, at_y: float, bw_x: float, bw_y: float,
                         seconds_per_count: float) -> float:
    """Paper eq. 7, ``Z = (A t)·td / (1 − (B ω)·td)`` metres; eq. 8 when ``bw = 0``.

    Meant for ``translational_share > 0`` (``classify_rotation`` rejects the rest);
    a zero share gives ``inf``, a negative one a depth of the wrong sign.
    """
    share = translational_share(signed_x, signed_y, bw_x, bw_y, seconds_per_count)
    numerator = float_depth(signed_x, signed_y, at_x, at_y, seconds_per_count)
    if share == 0.0:
        return math.inf
    return numerator / share


@njit(cache=True)
def classify_rotation(measured: bool, share, z, min_share, min_depth, max_depth) -> int:
    """``classify`` with eq. 7's extra test, in this order: no axis measured, then
    ``share <= min_share`` (ROTATION_DOMINATED), then the depth range. Floats or fixed-point ints.
    """
    if not measured:
        return NO_MEASUREMENT
    if share <= min_share:
        return ROTATION_DOMINATED
    return classify(measured, z, min_depth, max_depth)
