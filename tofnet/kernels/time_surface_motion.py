"""Motion helpers of the time-surface kernel (numba; used by ``tofnet.kernels.time_surface``).

The motion epochs of time coordinates (``follow_motion``), ``A t`` at a pixel, and the gains
``Aᵀ f`` and ``Bᵀ f`` that turn the camera's velocity and rotation into image motion along ``f``.
"""

from __future__ import annotations

import math

from numba import njit

from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.velocity import sampled_velocity_term, velocity_term

# Motion state: the velocity the current epoch started with, its start (µs), the last update seen.
M_VX, M_VY, M_VZ, M_SINCE, M_UPDATE, N_MOTION = range(6)


@njit(cache=True)
def follow_motion(motion, row, update: int, update_start_us: int, turn: float) -> None:
    """Start a new motion epoch at ``update`` when its velocity differs from the epoch's by more
    than ``turn`` times the epoch's speed (a turn, a start or a stop); ``turn = 0``: never."""
    dx, dy, dz = row[0] - motion[M_VX], row[1] - motion[M_VY], row[2] - motion[M_VZ]
    change = math.sqrt(dx * dx + dy * dy + dz * dz)
    speed = math.sqrt(motion[M_VX] ** 2 + motion[M_VY] ** 2 + motion[M_VZ] ** 2)
    if motion[M_UPDATE] < 0 or (turn > 0.0 and change > turn * speed):
        motion[M_VX], motion[M_VY], motion[M_VZ] = row[0], row[1], row[2]
        motion[M_SINCE] = update_start_us
    motion[M_UPDATE] = update


@njit(cache=True, inline="always")
def _velocity_term_at(x, y, pixel, per_pixel, pinhole, sample_of, points, tx, ty, tz, fx, fy, cx, cy):
    """``A t`` (px*m/s) for pixel (x, y) under the velocity (tx, ty, tz), through the lens of
    ``points`` (one ``tofnet.kernels.lens.sample_table`` row per sample: the pixel or its patch);
    ``pinhole`` (per pixel, no lens): at the pixel itself, the same numbers without reading the table."""
    if pinhole:
        at_x, at_y = velocity_term(tx, ty, tz, float(x), float(y), fx, fy, cx, cy)
    else:
        sample = pixel if per_pixel else sample_of[pixel]
        at_x, at_y = sampled_velocity_term(tx, ty, tz, points[sample], fx, fy, cx, cy)
    return at_x, at_y


@njit(cache=True, inline="always")
def _gains(x, y, pixel, per_pixel, pinhole, sample_of, points, fu, fv, fx, fy, cx, cy):
    """``g = Aᵀ f`` at pixel (x, y) (px per m/s of each velocity component, along ``f``): ``g·v = (A v)·f``."""
    if pinhole:
        return -fx * fu, -fy * fv, (x - cx) * fu + (y - cy) * fv
    sample = pixel if per_pixel else sample_of[pixel]
    ax, ay = sampled_velocity_term(1.0, 0.0, 0.0, points[sample], fx, fy, cx, cy)
    bx, by = sampled_velocity_term(0.0, 1.0, 0.0, points[sample], fx, fy, cx, cy)
    zx, zy = sampled_velocity_term(0.0, 0.0, 1.0, points[sample], fx, fy, cx, cy)
    return ax * fu + ay * fv, bx * fu + by * fv, zx * fu + zy * fv



@njit(cache=True, inline="always")
def _turn_gains(x, y, fu, fv, rfx, rfy, rcx, rcy):
    """``h = Bᵀ f`` at pixel (x, y) (px per rad of each rotation component, along ``f``): ``h·ω = (B ω)·f``."""
    ax, ay = rotational_flow(1.0, 0.0, 0.0, float(x), float(y), rfx, rfy, rcx, rcy)
    bx, by = rotational_flow(0.0, 1.0, 0.0, float(x), float(y), rfx, rfy, rcx, rcy)
    zx, zy = rotational_flow(0.0, 0.0, 1.0, float(x), float(y), rfx, rfy, rcx, rcy)
    return ax * fu + ay * fv, bx * fu + by * fv, zx * fu + zy * fv
