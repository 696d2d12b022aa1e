"""The velocity term ``A t`` of paper eq. 2 and where it is sampled (pixel or patch centre)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def velocity_term(tx: float, ty: float, tz: float, u: float, v: float,
                  fx: float, fy: float, cx: float, cy: float) -> tuple[float, float]:
    """``A t`` in px*m/s at image point (u, v) for camera velocity (tx, ty, tz) m/s."""
    return (-fx * tx + (u - cx) * tz, -fy * ty + (v - cy) * tz)


@njit(cache=True)
def sampled_velocity_term(tx: float, ty: float, tz: float, sample, fx: float, fy: float, cx: float,
                          cy: float) -> tuple[float, float]:
    """``J A(p') t`` px*m/s for one row of a lens sample table (``tofnet.kernels.lens``): ``A t``
    at the ideal point ``p'`` taken onto the raw sensor by ``J`` (exactly ``A(p) t`` for a pinhole)."""
    at_x, at_y = velocity_term(tx, ty, tz, sample[0], sample[1], fx, fy, cx, cy)
    return sample[2] * at_x + sample[3] * at_y, sample[4] * at_x + sample[5] * at_y


@njit(cache=True)
def sample_point(x: int, y: int, per_pixel: bool, patch_size: int, width: int, height: int) -> tuple[float, float]:
    """Where ``A t`` is evaluated for pixel (x, y): the pixel, or the centre of its patch.

    Patches tile the sensor from (0, 0); a ragged last patch uses its own centre.
    """
    if per_pixel:
        return (float(x), float(y))
    x0 = (x // patch_size) * patch_size
    y0 = (y // patch_size) * patch_size
    x1 = min(x0 + patch_size, width)
    y1 = min(y0 + patch_size, height)
    return ((x0 + x1 - 1) * 0.5, (y0 + y1 - 1) * 0.5)


def update_index(step, update_every: int):
    """Index of the velocity update a depth neuron holds in ``step`` (works on arrays).

    The velocity process sends in steps 0, U, 2U, ...; a value sent in step k arrives
    in step k+1, so the depth step ``s`` holds the update sent in the last multiple of
    U at or before ``s - 1``. Negative for ``s = 0`` (nothing arrived yet).
    """
    return (step - 1) // update_every


@njit(cache=True)
def sample_grid(per_pixel: bool, patch_size: int, width: int, height: int):
    """``sample_point`` for every pixel: arrays ``u, v`` of shape (height, width)."""
    u = np.empty((height, width), dtype=np.float64)
    v = np.empty((height, width), dtype=np.float64)
    for y in range(height):
        for x in range(width):
            u[y, x], v[y, x] = sample_point(x, y, per_pixel, patch_size, width, height)
    return u, v
