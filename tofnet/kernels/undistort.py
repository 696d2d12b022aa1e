"""Lens undistortion (OpenCV conventions): the per-pixel map and the event remap.

Two models, as ``Intrinsics.distortion_model`` names them: ``radtan`` (``k1 k2 p1 p2 k3``;
``calib.txt``, ROS ``plumb_bob``) and ``equidistant`` (``k1 k2 k3 k4``; OpenCV fisheye,
DSEC, M3ED), on normalised coordinates ``x = (u - cx) / fx``, ``y = (v - cy) / fy``.
A raw pixel is a distorted point; its undistorted image coordinates (px, same camera
matrix, as ``cv::undistortPoints`` with ``P = K``) are solved by Newton's method to
``1e-12`` in normalised units, which OpenCV's fixed five iterations do not guarantee at
strong distortion. The equations: docs/formats.md, "Lens distortion".
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tofnet.events import EVENT_DTYPE

MODELS = ("radtan", "equidistant")
_NEWTON_STEPS = 30
_TOLERANCE = 1e-12


def _coefficients(model: str, coefficients) -> np.ndarray:
    if model not in MODELS:
        raise ValueError(f"unknown distortion model {model!r}; expected one of {', '.join(MODELS)}")
    c = np.asarray(coefficients, dtype=np.float64).ravel()
    size = 5 if model == "radtan" else 4
    if c.size == 0:
        return np.zeros(size)
    if c.size != size:
        raise ValueError(f"{model} distortion needs {size} coefficients, got {c.size}")
    return c


def distort(x: np.ndarray, y: np.ndarray, model: str, coefficients) -> tuple[np.ndarray, np.ndarray]:
    """The forward model: ideal normalised ``(x, y)`` to distorted normalised ``(x_d, y_d)``."""
    c = _coefficients(model, coefficients)
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if model == "radtan":
        k1, k2, p1, p2, k3 = c
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
    r = np.hypot(x, y)
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1 + t2 * (c[0] + t2 * (c[1] + t2 * (c[2] + t2 * c[3]))))
    scale = np.divide(theta_d, r, out=np.ones_like(r), where=r > 1e-15)
    return x * scale, y * scale


def undistort(x_d: np.ndarray, y_d: np.ndarray, model: str, coefficients) -> tuple[np.ndarray, np.ndarray]:
    """The inverse: distorted normalised ``(x_d, y_d)`` to ideal normalised ``(x, y)`` (Newton).

    Points where the model cannot be inverted (beyond the fold of a strong barrel
    distortion) come out NaN.
    """
    c = _coefficients(model, coefficients)
    x_d, y_d = np.asarray(x_d, dtype=np.float64), np.asarray(y_d, dtype=np.float64)
    if model == "equidistant":
        return _undistort_equidistant(x_d, y_d, c)
    x, y = x_d.copy(), y_d.copy()
    k1, k2, p1, p2, k3 = c
    for _ in range(_NEWTON_STEPS):
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        d_radial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
        fx_ = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - x_d
        fy_ = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - y_d
        a = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
        b = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
        d = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
        e = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
        det = a * e - b * d
        step_x = (e * fx_ - b * fy_) / det
        step_y = (a * fy_ - d * fx_) / det
        x, y = x - step_x, y - step_y
        if np.nanmax(np.abs(step_x) + np.abs(step_y), initial=0.0) < _TOLERANCE:
            break
    residual = np.hypot(*(np.subtract(distort(x, y, model, c), (x_d, y_d))))
    bad = ~(residual < 1e-9)
    x[bad] = np.nan
    y[bad] = np.nan
    return x, y


def _undistort_equidistant(x_d, y_d, c) -> tuple[np.ndarray, np.ndarray]:
    theta_d = np.hypot(x_d, y_d)
    theta = theta_d.copy()
    for _ in range(_NEWTON_STEPS):
        t2 = theta * theta
        value = theta * (1 + t2 * (c[0] + t2 * (c[1] + t2 * (c[2] + t2 * c[3])))) - theta_d
        slope = 1 + t2 * (3 * c[0] + t2 * (5 * c[1] + t2 * (7 * c[2] + t2 * 9 * c[3])))
        step = value / slope
        theta = theta - step
        if np.nanmax(np.abs(step), initial=0.0) < _TOLERANCE:
            break
    scale = np.divide(np.tan(theta), theta_d, out=np.ones_like(theta_d), where=theta_d > 1e-15)
    bad = ~((theta >= 0) & (theta < np.pi / 2))
    scale[bad] = np.nan
    return x_d * scale, y_d * scale


def undistortion_map(intrinsics, sensor_size: tuple[int, int]) -> np.ndarray:
    """``(height, width, 2)`` float64: the undistorted image coordinates ``(u, v)`` of each raw pixel.

    Same camera matrix before and after (``P = K``); NaN where the model has no inverse.
    """
    width, height = (int(v) for v in sensor_size)
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    x_d = (u - intrinsics.cx) / intrinsics.fx
    y_d = (v - intrinsics.cy) / intrinsics.fy
    x, y = undistort(x_d, y_d, intrinsics.distortion_model, intrinsics.distortion)
    return np.stack([x * intrinsics.fx + intrinsics.cx, y * intrinsics.fy + intrinsics.cy], axis=-1)


def pixel_targets(pixel_map: np.ndarray, image_size: tuple[int, int] | None = None) -> np.ndarray:
    """``(height, width)`` int64 of the map: ``v' * width + u'``, the undistorted pixel each raw pixel
    moves to (nearest, halves up), or -1 where that pixel lies outside the ``image_size``
    (width, height; default the map's) image or the model has no inverse (NaN)."""
    height, width = pixel_map.shape[:2]
    if image_size is not None:
        width, height = (int(v) for v in image_size)
    with np.errstate(invalid="ignore"):
        u, v = np.floor(pixel_map[..., 0] + 0.5), np.floor(pixel_map[..., 1] + 0.5)
        inside = (u >= 0) & (v >= 0) & (u < width) & (v < height)  # False for NaN
    targets = np.full(u.shape, -1, dtype=np.int64)
    targets[inside] = v[inside].astype(np.int64) * width + u[inside].astype(np.int64)
    return targets


@njit(cache=True)
def _remap(t, x, y, p, targets, width, out_t, out_x, out_y, out_p, counts):
    n_out = 0
    map_height, map_width = targets.shape
    for i in range(t.shape[0]):
        if x[i] >= map_width or y[i] >= map_height:
            counts[1] += 1
            continue
        target = targets[y[i], x[i]]
        if target < 0:
            counts[0] += 1
            continue
        out_t[n_out] = t[i]
        out_x[n_out] = np.uint16(target % width)
        out_y[n_out] = np.uint16(target // width)
        out_p[n_out] = p[i]
        n_out += 1
    return n_out


def remap_events(events: np.ndarray, pixel_map: np.ndarray,
                 image_size: tuple[int, int] | None = None) -> tuple[np.ndarray, dict[str, int]]:
    """Move each event to its undistorted pixel (nearest, halves up); count what leaves the image.

    ``pixel_map`` is ``undistortion_map(...)``; ``image_size`` (width, height) of the
    output image defaults to the map's. Returns the kept events (new array, same order)
    and ``{"left_image": n, "beyond_map": n}``: events whose undistorted pixel falls
    outside the image (or has no inverse), and events whose raw pixel lies outside the map.
    """
    targets = pixel_targets(pixel_map, image_size)
    width = pixel_map.shape[1] if image_size is None else int(image_size[0])
    n = len(events)
    out_t, out_x = np.empty(n, np.int64), np.empty(n, np.uint16)
    out_y, out_p = np.empty(n, np.uint16), np.empty(n, np.uint8)
    counts = np.zeros(2, dtype=np.int64)
    kept = _remap(np.ascontiguousarray(events["t"]), np.ascontiguousarray(events["x"]),
                  np.ascontiguousarray(events["y"]), np.ascontiguousarray(events["p"]),
                  targets, width, out_t, out_x, out_y, out_p, counts)
    out = np.empty(kept, dtype=EVENT_DTYPE)
    out["t"], out["x"], out["y"], out["p"] = out_t[:kept], out_x[:kept], out_y[:kept], out_p[:kept]
    return out, {"left_image": int(counts[0]), "beyond_map": int(counts[1])}


NEVER_STEP = -(1 << 62)  # "no spike yet" in ``remap_spikes``'s ``last_step``


@njit(cache=True)
def remap_spikes(step, x, y, p, targets, width, last_step, out, counts):
    """Spikes (received step, raw x, y, polarity; sorted by step, then y, x) moved to their undistorted pixel.

    ``targets`` is ``pixel_targets``; ``last_step[target]`` the latest step the undistorted
    pixel was sent a spike (``NEVER_STEP`` before). Within a step the first spike (in the
    given order) to land on a pixel is sent, later ones are counted ``merged`` (one spike per
    pixel and step); a spike whose pixel has no target is counted ``left_image``. Each step's
    spikes go to ``out`` stamped with the step, sorted by (y, x) of the undistorted pixel;
    ``counts`` = [passed, left_image, merged]. Returns how many were sent.
    """
    n = step.shape[0]
    map_height, map_width = targets.shape
    keys = np.empty(n, dtype=np.int64)
    kept = np.empty(n, dtype=np.int64)
    n_out = 0
    i = 0
    while i < n:
        k = step[i]
        j = i
        m = 0
        while j < n and step[j] == k:
            xi, yi = np.int64(x[j]), np.int64(y[j])
            target = targets[yi, xi] if xi < map_width and yi < map_height else -1
            if target < 0:
                counts[1] += 1
            elif last_step[target] == k:
                counts[2] += 1
            else:
                last_step[target] = k
                keys[m] = target
                kept[m] = j
                m += 1
            j += 1
        order = np.argsort(keys[:m])
        for q in range(m):
            target = keys[order[q]]
            out[n_out].step = k
            out[n_out].x = np.uint16(target % width)
            out[n_out].y = np.uint16(target // width)
            out[n_out].p = p[kept[order[q]]]
            n_out += 1
        counts[0] += m
        i = j
    return n_out
