"""Ray casting of a packed scene, and the render times that keep the image steps small.

One ray per pixel centre: the nearest rectangle hit gives the depth (camera-frame z,
which equals the ray parameter because rays are ``((u-cx)/fx, (v-cy)/fy, 1)``) and a
bilinearly sampled, shaded texture value, whose log is what the pixels see.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tofnet.io.recording import Intrinsics
from tofnet.sim.camera import Trajectory
from tofnet.sim.errors import SimError
from tofnet.sim.lens import PixelRays, pixel_rays
from tofnet.sim.scene import PackedScene

#: Offset in ``log(intensity + LOG_EPS)``, as ESIM (intensities are in (0, 1]).
LOG_EPS = 1e-3
#: The camera must stay this far (m) in front of every object corner.
MIN_CLEARANCE = 0.05


@njit(cache=True)
def _render(cam, fx, fy, cx, cy, width, height, ray_x, ray_y, distorted, col_lo, col_hi, row_lo, row_hi,
            centers, axes_u, axes_v, normals, half, one_sided, shade,
            texel, tex_offset, tex_shape, tex_flat, log_eps, out_log, out_depth):  # pragma: no cover - numba
    """Fill ``out_log`` (log intensity) and ``out_depth`` (m; NaN where no rectangle is hit), raveled rows.

    Pixel ``i`` casts the ray ``(ray_x[i], ray_y[i], 1)`` (``tofnet.sim.lens``). Face by face
    with a depth buffer; each face only tests the pixels inside the bounding box of its
    projected corners (the whole image if a corner is behind the camera): for a pinhole
    the box itself, through a distorted lens the columns and rows whose ideal image
    coordinates (``col_lo .. col_hi``, ``row_lo .. row_hi``) reach into it.
    """
    nf = centers.shape[0]
    npix = width * height
    best = np.full(npix, np.inf)
    hit = np.full(npix, -1, dtype=np.int64)
    hit_a = np.empty(npix)
    hit_b = np.empty(npix)
    rel = np.empty(3)
    for k in range(nf):
        num = 0.0
        for j in range(3):
            rel[j] = cam[j] - centers[k, j]
            num -= normals[k, j] * rel[j]
        if one_sided[k] and num >= 0.0:
            continue  # a box face turned away from the camera
        u0, u1, v0, v1 = 0, width - 1, 0, height - 1
        umin, umax, vmin, vmax = np.inf, -np.inf, np.inf, -np.inf
        behind = False
        for su in (-1.0, 1.0):
            for sv in (-1.0, 1.0):
                x = -rel[0] + su * half[k, 0] * axes_u[k, 0] + sv * half[k, 1] * axes_v[k, 0]
                y = -rel[1] + su * half[k, 0] * axes_u[k, 1] + sv * half[k, 1] * axes_v[k, 1]
                z = -rel[2] + su * half[k, 0] * axes_u[k, 2] + sv * half[k, 1] * axes_v[k, 2]
                if z <= 1e-9:
                    behind = True
                else:
                    pu = cx + fx * x / z
                    pv = cy + fy * y / z
                    umin, umax = min(umin, pu), max(umax, pu)
                    vmin, vmax = min(vmin, pv), max(vmax, pv)
        if not behind:
            # One pixel of margin: the corners' projection bounds the face exactly.
            if (umax < col_lo.min() - 1.0 or vmax < row_lo.min() - 1.0 or umin > col_hi.max() + 1.0
                    or vmin > row_hi.max() + 1.0):
                continue
            if distorted:
                u0, u1, v0, v1 = width, -1, height, -1
                for c in range(width):
                    if col_hi[c] >= umin - 1.0 and col_lo[c] <= umax + 1.0:
                        u0, u1 = min(u0, c), max(u1, c)
                for r in range(height):
                    if row_hi[r] >= vmin - 1.0 and row_lo[r] <= vmax + 1.0:
                        v0, v1 = min(v0, r), max(v1, r)
            else:
                u0 = max(0, int(np.floor(umin)) - 1)
                u1 = min(width - 1, int(np.ceil(umax)) + 1)
                v0 = max(0, int(np.floor(vmin)) - 1)
                v1 = min(height - 1, int(np.ceil(vmax)) + 1)
        for v in range(v0, v1 + 1):
            for u in range(u0, u1 + 1):
                i = v * width + u
                dx = ray_x[i]
                dy = ray_y[i]
                den = normals[k, 0] * dx + normals[k, 1] * dy + normals[k, 2]
                if den == 0.0:
                    continue
                t = num / den
                if t <= 0.0 or t >= best[i]:
                    continue
                px = rel[0] + t * dx
                py = rel[1] + t * dy
                pz = rel[2] + t
                a = px * axes_u[k, 0] + py * axes_u[k, 1] + pz * axes_u[k, 2]
                if abs(a) > half[k, 0]:
                    continue
                b = px * axes_v[k, 0] + py * axes_v[k, 1] + pz * axes_v[k, 2]
                if abs(b) > half[k, 1]:
                    continue
                best[i] = t
                hit[i] = k
                hit_a[i] = a
                hit_b[i] = b
    for i in range(npix):
        k = hit[i]
        if k < 0:
            out_depth[i] = np.nan
            out_log[i] = 0.0
            continue
        rows = tex_shape[k, 0]
        cols = tex_shape[k, 1]
        # Texel (r, c) is centred at a = (c + 0.5) * texel - cols * texel / 2.
        fc = min(max(hit_a[i] / texel[k] + 0.5 * cols - 0.5, 0.0), cols - 1.0)
        fr = min(max(hit_b[i] / texel[k] + 0.5 * rows - 0.5, 0.0), rows - 1.0)
        c0 = min(int(fc), cols - 2)
        r0 = min(int(fr), rows - 2)
        wc = fc - c0
        wr = fr - r0
        base = tex_offset[k] + r0 * cols + c0
        val = ((1 - wr) * ((1 - wc) * tex_flat[base] + wc * tex_flat[base + 1])
               + wr * ((1 - wc) * tex_flat[base + cols] + wc * tex_flat[base + cols + 1]))
        out_depth[i] = best[i]
        out_log[i] = math.log(val * shade[k] + log_eps)


@njit(cache=True)
def max_flow(depth, vx, vy, vz, fx, fy, cx, cy, width):  # pragma: no cover - numba
    """Largest image speed (px/s) over pixels: ``|A t| / Z`` for velocity ``(vx, vy, vz)`` m/s."""
    best = 0.0
    for i in range(depth.shape[0]):
        u = i % width
        v = i // width
        fu = -fx * vx + (u - cx) * vz
        fv = -fy * vy + (v - cy) * vz
        s = math.sqrt(fu * fu + fv * fv) / depth[i]
        if s > best:
            best = s
    return best


class Renderer:
    """Renders ``scene`` for camera positions; holds the output buffers."""

    def __init__(self, scene: PackedScene, intrinsics: Intrinsics, sensor_size: tuple[int, int],
                 rays: PixelRays | None = None) -> None:
        self.scene = scene
        self.intrinsics = intrinsics
        self.width, self.height = sensor_size
        self.rays = rays if rays is not None else pixel_rays(intrinsics, sensor_size)

    def render(self, position: np.ndarray, rotation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(log_intensity, depth)`` float64 arrays of ``width * height`` (row-major) at ``position`` (m).

        ``rotation`` is the camera-to-world ``R_wc`` (3x3) of a turning camera; without
        it the camera frame is the world frame. A turned camera renders the scene moved
        into its frame (``R_wc^T (P − c)``, face by face), so depth stays camera-frame z.
        """
        n = self.width * self.height
        log_i, depth = np.empty(n), np.empty(n)
        s, k = self.scene, self.intrinsics
        cam, centers, axes_u, axes_v, normals = (np.ascontiguousarray(position, dtype=np.float64), s.centers,
                                                 s.axes_u, s.axes_v, s.normals)
        if rotation is not None:
            r = np.asarray(rotation, dtype=np.float64)
            # Rows times R is R^T applied to each row.
            centers, axes_u, axes_v, normals = (np.ascontiguousarray(a) for a in
                                                ((s.centers - cam) @ r, s.axes_u @ r, s.axes_v @ r, s.normals @ r))
            cam = np.zeros(3)
        rays = self.rays
        _render(cam, k.fx, k.fy, k.cx, k.cy, self.width, self.height, rays.x, rays.y, rays.distorted, rays.col_lo,
                rays.col_hi, rays.row_lo, rays.row_hi, centers, axes_u, axes_v, normals, s.half, s.one_sided, s.shade,
                s.texel, s.tex_offset, s.tex_shape, s.tex_flat, LOG_EPS, log_i, depth)
        if np.isnan(depth).any():
            i = int(np.flatnonzero(np.isnan(depth))[0])
            raise SimError(f"scene: the ray of pixel (x={i % self.width}, y={i // self.width}) hits nothing at camera "
                           f"position {tuple(np.round(position, 4))} m; expected a background behind every object")
        return log_i, depth


def flow_bound(velocity: np.ndarray, z_min: float, intrinsics: Intrinsics, sensor_size: tuple[int, int],
               rays: PixelRays | None = None) -> float:
    """Upper bound (px/s) of the image speed ``|A t| / Z`` over the sensor when every depth is >= ``z_min`` m.

    ``|A t|`` is convex in the pixel position, so its maximum is at a sensor corner. Through a
    distorted lens (``rays``) the corners are those of the ideal image the sensor sees, and the
    bound is scaled by the lens's largest magnification of image motion (``rays.flow_scale``).
    """
    k = intrinsics
    w, h = sensor_size
    u_lo, u_hi, v_lo, v_hi = (-0.5, w - 0.5, -0.5, h - 0.5) if rays is None or not rays.distorted else rays.extent(k)
    scale = 1.0 if rays is None else rays.flow_scale
    best = 0.0
    for u in (u_lo, u_hi):
        for v in (v_lo, v_hi):
            fu = -k.fx * velocity[0] + (u - k.cx) * velocity[2]
            fv = -k.fy * velocity[1] + (v - k.cy) * velocity[2]
            best = max(best, math.hypot(fu, fv))
    return scale * best / z_min


def render_times(trajectory: Trajectory, duration: float, min_z: float, intrinsics: Intrinsics,
                 sensor_size: tuple[int, int], max_step_px: float = 0.25, rays: PixelRays | None = None) -> np.ndarray:
    """Render times (s) from 0 to ``duration`` such that no image point moves more than ``max_step_px`` between two.

    Every segment boundary is a render time (so each interval has one velocity), and
    within a segment renders are evenly spaced by ``max_step_px / flow_bound``, with
    the nearest depth bounded by ``min_z`` (the scene's nearest world z) minus the
    camera's largest z in the segment: a bound that holds for every visible point.
    """
    bounds = trajectory.boundaries
    edges = np.unique(np.clip(np.concatenate([bounds, [duration]]), 0.0, duration))
    times = [np.zeros(1)]
    for t0, t1 in zip(edges[:-1], edges[1:]):
        mid = 0.5 * (t0 + t1)
        vel = trajectory.velocity_at(mid)[0]
        cam_z = max(trajectory.position_at(t0)[0, 2], trajectory.position_at(t1)[0, 2])
        z_near = min_z - cam_z
        if z_near < MIN_CLEARANCE:
            raise SimError(f"trajectory: between t = {t0:.4g} s and {t1:.4g} s the camera (z up to {cam_z:.3g} m) comes "
                           f"within {MIN_CLEARANCE} m of the scene's nearest point (z = {min_z:.3g} m); expected the "
                           f"camera to stay in front of every object")
        flow = flow_bound(vel, z_near, intrinsics, sensor_size, rays)
        n = max(1, int(math.ceil((t1 - t0) * flow / max_step_px)))
        times.append(np.linspace(t0, t1, n + 1)[1:])
    return np.concatenate(times)
