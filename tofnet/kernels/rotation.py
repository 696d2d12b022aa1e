"""The rotational image flow ``B ω`` of paper eq. 7, per pixel (px/s).

A static point seen by a camera turning at ``ω`` rad/s (camera frame: x right, y down,
z forward) moves in the image at ``B ω`` whatever its depth, so the image velocity is
``A t / Z + B ω``. The formula (Longuet-Higgins & Prazdny, for ``fx != fy``; the paper
prints B with typos) and its derivation: docs/rotation.md, "The equation";
``tests/test_rotation_kernels.py`` checks the signs against a projected point.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def rotational_flow(wx: float, wy: float, wz: float, u: float, v: float,
                    fx: float, fy: float, cx: float, cy: float) -> tuple[float, float]:
    """``B ω`` in px/s at image point ``(u, v)`` px for angular velocity ``(wx, wy, wz)`` rad/s."""
    x = u - cx
    y = v - cy
    flow_u = (x * y / fy) * wx - (fx + x * x / fx) * wy + (fx / fy) * y * wz
    flow_v = (fy + y * y / fy) * wx - (x * y / fx) * wy - (fy / fx) * x * wz
    return (flow_u, flow_v)


@njit(cache=True)
def rotational_flow_grid(wx: float, wy: float, wz: float, width: int, height: int,
                         fx: float, fy: float, cx: float, cy: float):
    """``rotational_flow`` at every pixel centre: arrays ``(flow_u, flow_v)`` of shape (height, width), px/s."""
    flow_u = np.empty((height, width), dtype=np.float64)
    flow_v = np.empty((height, width), dtype=np.float64)
    for y in range(height):
        for x in range(width):
            flow_u[y, x], flow_v[y, x] = rotational_flow(wx, wy, wz, float(x), float(y), fx, fy, cx, cy)
    return flow_u, flow_v


@njit(cache=True)
def rotational_flow_bound(wx: float, wy: float, wz: float, width: int, height: int,
                          fx: float, fy: float, cx: float, cy: float) -> float:
    """An upper bound (px/s) of ``|B ω|`` over the sensor, pixel edges included.

    Each term of ``flow_u`` and ``flow_v`` is bounded by its value at the largest
    ``|x|`` and ``|y|``; cheap, and tight enough to pace a renderer.
    """
    ax = max(abs(-0.5 - cx), abs(width - 0.5 - cx))
    ay = max(abs(-0.5 - cy), abs(height - 0.5 - cy))
    bu = (ax * ay / fy) * abs(wx) + (fx + ax * ax / fx) * abs(wy) + (fx / fy) * ay * abs(wz)
    bv = (fy + ay * ay / fy) * abs(wx) + (ax * ay / fx) * abs(wy) + (fy / fx) * ax * abs(wz)
    return (bu * bu + bv * bv) ** 0.5
