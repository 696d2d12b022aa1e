"""The simulated lens: the ray each sensor pixel sees, for a pinhole or a distorted lens.

A pinhole pixel ``(u, v)`` looks along ``((u - cx)/fx, (v - cy)/fy, 1)``. Through a lens
with distortion (``Intrinsics.distortion``, OpenCV's ``radtan`` or ``equidistant``), the
pixel sees the scene point whose ideal projection distorts onto the pixel: its ray is the
undistorted normalised point of ``(u, v)`` (``tofnet.kernels.undistort``). The renderer
casts these rays, so the events, their ground-truth depth and the recording's
``calib.txt`` describe one physical camera with that lens.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.io.recording import Intrinsics
from tofnet.sim.errors import SimError


@dataclass(frozen=True)
class PixelRays:
    """Per pixel (row-major, ``width * height``): the ray slopes ``x``, ``y``; per column and row: the range of
    the pixels' ideal (pinhole) image coordinates, px (``col_lo/col_hi``: u, ``row_lo/row_hi``: v), which the
    renderer bounds each face's pixels with; ``fov`` the ray slopes ``(left, right, top, bottom)`` of the
    sensor's outer edges; ``flow_scale`` the largest factor by which the lens magnifies image motion
    (1 for a pinhole); ``distorted`` whether the lens bends rays at all."""

    x: np.ndarray
    y: np.ndarray
    col_lo: np.ndarray
    col_hi: np.ndarray
    row_lo: np.ndarray
    row_hi: np.ndarray
    fov: tuple[float, float, float, float]
    flow_scale: float
    distorted: bool

    def extent(self, k: Intrinsics) -> tuple[float, float, float, float]:
        """``(u_lo, u_hi, v_lo, v_hi)``: the ideal image coordinates (px) of the sensor's outer edges."""
        left, right, top, bottom = self.fov
        return (k.cx + k.fx * left, k.cx + k.fx * right, k.cy + k.fy * top, k.cy + k.fy * bottom)


def pixel_rays(k: Intrinsics, sensor_size: tuple[int, int]) -> PixelRays:
    """The rays of every pixel of a ``sensor_size`` (width, height) sensor behind lens ``k``."""
    width, height = sensor_size
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    distorted = any(c != 0 for c in k.distortion)
    if not distorted:
        x, y = (u - k.cx) / k.fx, (v - k.cy) / k.fy
        fov = (-(k.cx + 0.5) / k.fx, (width - 0.5 - k.cx) / k.fx, -(k.cy + 0.5) / k.fy, (height - 0.5 - k.cy) / k.fy)
        columns, rows = np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64)
        return PixelRays(x.ravel(), y.ravel(), columns, columns.copy(), rows, rows.copy(), fov, 1.0, False)
    from tofnet.kernels.undistort import undistort

    def rays_of(pu, pv):
        try:
            return undistort((pu - k.cx) / k.fx, (pv - k.cy) / k.fy, k.distortion_model, k.distortion)
        except ValueError as err:
            raise SimError(f"intrinsics: {err}") from None

    x, y = rays_of(u, v)
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise SimError(f"intrinsics: the {k.distortion_model} lens {tuple(k.distortion)} has no inverse at some pixels "
                       f"of the {width}x{height} sensor (beyond the fold of its distortion); expected a lens that "
                       "maps every pixel to a ray")
    ideal_u, ideal_v = k.cx + k.fx * x, k.cy + k.fy * y
    # The sensor's outer edges (half a pixel beyond the outer centres), sampled finely.
    eu = np.concatenate([np.linspace(-0.5, width - 0.5, 4 * width)] * 2 + [np.full(4 * height, -0.5),
                                                                        np.full(4 * height, width - 0.5)])
    ev = np.concatenate([np.full(4 * width, -0.5), np.full(4 * width, height - 0.5)] +
                        [np.linspace(-0.5, height - 0.5, 4 * height)] * 2)
    ex, ey = rays_of(eu, ev)
    if not (np.isfinite(ex).all() and np.isfinite(ey).all()):
        raise SimError(f"intrinsics: the {k.distortion_model} lens has no inverse at the sensor's edge")
    fov = (float(min(ex.min(), x.min())), float(max(ex.max(), x.max())),
           float(min(ey.min(), y.min())), float(max(ey.max(), y.max())))
    # Image motion through the lens: one sensor pixel spans |d ideal| ideal pixels, so the lens
    # scales motion by 1 / |d ideal| (largest where the ideal image is compressed most).
    spacing = min(np.hypot(np.diff(ideal_u, axis=1), np.diff(ideal_v, axis=1)).min(),
                  np.hypot(np.diff(ideal_u, axis=0), np.diff(ideal_v, axis=0)).min())
    return PixelRays(x.ravel(), y.ravel(), ideal_u.min(axis=0), ideal_u.max(axis=0), ideal_v.min(axis=1),
                     ideal_v.max(axis=1), fov, float(max(1.0, 1.0 / spacing)), True)
