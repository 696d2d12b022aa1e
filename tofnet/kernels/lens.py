"""The velocity term ``A t`` seen through a distorted lens, per sample of the depth layer.

A time-of-travel unit times an edge between two *raw* neighbouring pixels, so the depth
neuron needs the edge's velocity on the raw sensor: each sample (a pixel, or a patch
centre) gets, once, its ideal point ``p'`` and the distortion's Jacobian ``J = d raw /
d ideal`` there, and the depth neurons use ``J A(p') t`` (px·m/s) where the pinhole network
uses ``A(p) t``. Without distortion ``p' = p`` and ``J = I``, exactly. Why this keeps eq. 8
on the raw pixels: docs/formats.md, "In the network: through the velocity term".
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from tofnet.kernels.undistort import distort, undistort
from tofnet.kernels.velocity import sample_grid

#: A lens as the kernels take it: (distortion model, coefficients); None is a pinhole.
Lens = tuple[str, tuple[float, ...]]
#: Columns of a sample table: the ideal point (u', v') px and J row by row.
SAMPLE_COLUMNS = 6
_STEP = 1e-6  # central differences in normalised units: error ~1e-12, rounding ~1e-10


def lens_of(intrinsics) -> Lens | None:
    """The lens of an ``Intrinsics`` (None when it has no non-zero distortion coefficient)."""
    coefficients = tuple(float(c) for c in (intrinsics.distortion or ()))
    if not any(c != 0 for c in coefficients):
        return None
    return (str(intrinsics.distortion_model), coefficients)


def lens_jacobian(u: np.ndarray, v: np.ndarray, camera: tuple[float, float, float, float],
                  lens: Lens) -> np.ndarray:
    """For raw points ``(u, v)`` px: ``(..., 6)``, their ideal points ``(u', v')`` px and
    ``J = d raw / d ideal`` at them (``J00 J01 J10 J11``, dimensionless).

    Where the lens has no inverse (beyond the fold of a strong barrel distortion) the point
    is kept as it is with ``J = I``: the pinhole velocity term.
    """
    fx, fy, cx, cy = camera
    model, coefficients = lens
    u, v = (np.ascontiguousarray(a) for a in np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64)))
    x, y = undistort((u - cx) / fx, (v - cy) / fy, model, coefficients)
    dxu, dyu = distort(x + _STEP, y, model, coefficients)
    dxl, dyl = distort(x - _STEP, y, model, coefficients)
    dxd, dyd = distort(x, y + _STEP, model, coefficients)
    dxb, dyb = distort(x, y - _STEP, model, coefficients)
    table = np.empty(np.shape(x) + (SAMPLE_COLUMNS,))
    table[..., 0], table[..., 1] = fx * x + cx, fy * y + cy
    # normalised derivatives to pixels: raw_u = fx x_d + cx, ideal_u = fx x + cx (likewise v)
    table[..., 2] = (dxu - dxl) / (2 * _STEP)
    table[..., 3] = (dxd - dxb) / (2 * _STEP) * (fx / fy)
    table[..., 4] = (dyu - dyl) / (2 * _STEP) * (fy / fx)
    table[..., 5] = (dyd - dyb) / (2 * _STEP)
    lost = ~np.all(np.isfinite(table), axis=-1)
    table[lost] = np.stack([u[lost], v[lost], *(np.full(int(lost.sum()), c) for c in (1.0, 0.0, 0.0, 1.0))],
                           axis=-1)
    return table


@lru_cache(maxsize=16)
def sample_table(per_pixel: bool, patch_size: int, sensor_size: tuple[int, int],
                 camera: tuple[float, float, float, float], lens: Lens | None) -> np.ndarray:
    """``(height, width, 6)`` read-only: for every pixel, the ideal point where its ``A t`` is
    evaluated and the ``J`` that takes it to the sensor (``tofnet.kernels.velocity.sample_point``
    for the raw point; ``(u, v, 1, 0, 0, 1)`` without a lens). Computed once per lens and grid,
    for the whole sensor, so that every region and backend reads the same numbers."""
    width, height = (int(s) for s in sensor_size)
    u, v = sample_grid(bool(per_pixel), int(patch_size), width, height)
    table = np.empty((height, width, SAMPLE_COLUMNS))
    if lens is None:
        table[..., 0], table[..., 1], table[..., 2:] = u, v, (1.0, 0.0, 0.0, 1.0)
    else:  # u depends on the column only and v on the row only: solve each distinct point once
        cols, col_of = np.unique(u[0], return_inverse=True)
        rows, row_of = np.unique(v[:, 0], return_inverse=True)
        distinct = lens_jacobian(cols[None, :], rows[:, None], camera, lens)
        table[...] = distinct[row_of.ravel()[:, None], col_of.ravel()[None, :]]
    table.flags.writeable = False
    return table
