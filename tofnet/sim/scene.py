"""Static scenes of textured rectangles: planes (fronto-parallel or tilted), boxes, a background.

A scene is plain data (frozen dataclasses, metres, radians, world frame = the
camera frame at zero position: x right, y down, z forward). ``pack_scene`` turns it
into flat arrays of rectangles with their texture images, which the renderer
ray-casts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tofnet.sim.errors import SimError
from tofnet.sim.texture import Texture, make_texture

#: Direction towards the light (world frame: up, towards the camera, a little left);
#: it only shades faces differently so that box edges show.
LIGHT = np.array([-0.3, -0.8, -0.5]) / math.sqrt(0.98)
#: Shade of a face: ``AMBIENT + (1 - AMBIENT) * |n . LIGHT|``.
AMBIENT = 0.6
#: Largest texture side in texels; beyond it texels grow instead.
MAX_TEXELS = 4096


@dataclass(frozen=True)
class Plane:
    """A textured rectangle of ``size = (width, height)`` m centred at ``center`` (m).

    Unrotated, its u axis is world x and its v axis world y (fronto-parallel). ``yaw``
    turns it about the world y axis (positive: the right side recedes), then ``pitch``
    about its own x axis (positive: the bottom recedes), radians. Seen from both sides.
    """

    center: tuple[float, float, float]
    size: tuple[float, float]
    texture: Texture = field(default_factory=Texture)
    yaw: float = 0.0
    pitch: float = 0.0
    name: str = "plane"


@dataclass(frozen=True)
class Box:
    """An axis-aligned box (then turned by ``yaw`` about world y) of ``size = (sx, sy, sz)`` m."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    texture: Texture = field(default_factory=Texture)
    yaw: float = 0.0
    name: str = "box"


@dataclass(frozen=True)
class Scene:
    """Objects in front of the camera and a fronto-parallel background at world z = ``background_depth``.

    The background is as large as every ray of the trajectory needs, so every pixel
    sees something.
    """

    objects: tuple[Plane | Box, ...]
    background_depth: float = 3.0
    background: Texture = field(default_factory=lambda: Texture("shapes", scale=0.25))


@dataclass
class PackedScene:
    """Flat arrays of ``F`` rectangles, ready for the renderer (see ``tofnet.sim.render``)."""

    centers: np.ndarray      # (F, 3) m
    axes_u: np.ndarray       # (F, 3) unit
    axes_v: np.ndarray       # (F, 3) unit
    normals: np.ndarray      # (F, 3) unit, u x v; outward for box faces
    half: np.ndarray         # (F, 2) m, half extents along u and v
    one_sided: np.ndarray    # (F,) uint8, 1 = box face, culled when facing away
    shade: np.ndarray        # (F,) factor applied to the texture
    texel: np.ndarray        # (F,) m
    tex_offset: np.ndarray   # (F,) int64 start in tex_flat
    tex_shape: np.ndarray    # (F, 2) int64 rows, cols
    tex_flat: np.ndarray     # float32, every texture image raveled
    names: list[str]
    min_z: float             # smallest world z of any corner, m


def _rotation(yaw: float, pitch: float) -> np.ndarray:
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    return ry @ rx


def _faces(obj: Plane | Box) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray, tuple[float, float], bool]]:
    """``(name, center, u, v, half, one_sided)`` of each rectangle of ``obj``."""
    center = np.asarray(obj.center, dtype=np.float64)
    if isinstance(obj, Plane):
        rot = _rotation(obj.yaw, obj.pitch)
        return [(obj.name, center, rot[:, 0], rot[:, 1], (obj.size[0] / 2, obj.size[1] / 2), False)]
    rot = _rotation(obj.yaw, 0.0)
    half = np.asarray(obj.size, dtype=np.float64) / 2
    faces = []
    for axis, label in ((0, "x"), (1, "y"), (2, "z")):
        for sign in (1.0, -1.0):
            n = sign * rot[:, axis]
            up = rot[:, 2] if axis == 1 else rot[:, 1]  # any in-face direction
            v = up - (up @ n) * n
            v /= np.linalg.norm(v)
            u = np.cross(v, n)  # so that u x v = n, outward
            # u and v are box axes (up to sign): take the half extent along each.
            hu = half[int(np.argmax(np.abs(rot.T @ u)))]
            hv = half[int(np.argmax(np.abs(rot.T @ v)))]
            faces.append((f"{obj.name} face {'+' if sign > 0 else '-'}{label}", center + n * half[axis], u, v,
                          (hu, hv), True))
    return faces


def _check(obj: Plane | Box, i: int) -> None:
    what = f"scene object {i} ({obj.name!r})"
    if len(obj.center) != 3 or not all(math.isfinite(c) for c in obj.center):
        raise SimError(f"{what} center: expected 3 finite coordinates in metres, got {obj.center!r}")
    dims = 2 if isinstance(obj, Plane) else 3
    if len(obj.size) != dims or not all(math.isfinite(s) and s > 0 for s in obj.size):
        raise SimError(f"{what} size: expected {dims} positive lengths in metres, got {obj.size!r}")


def pack_scene(scene: Scene, *, focal: float, camera_box: tuple[np.ndarray, np.ndarray],
               fov: tuple[float, float, float, float], seed: int) -> PackedScene:
    """Flatten ``scene`` and make its textures.

    Parameters
    ----------
    focal : largest focal length, pixels; one texel is about one pixel at a face's
        distance from the camera's mean position.
    camera_box : ``(lo, hi)`` corners (m) of the box holding every camera position.
    fov : ``(left, right, top, bottom)`` ray slopes ``(u - cx)/fx``, ``(v - cy)/fy`` of
        the sensor's outer edges; the background is made to cover them.
    seed : textures are drawn from ``seed`` and the face's index, so one face's
        texture does not change when another object is added after it.
    """
    lo, hi = (np.asarray(c, dtype=np.float64) for c in camera_box)
    mean_cam = (lo + hi) / 2
    faces = []
    for i, obj in enumerate(scene.objects):
        if not isinstance(obj, (Plane, Box)):
            raise SimError(f"scene object {i}: expected a Plane or a Box, got {type(obj).__name__}")
        _check(obj, i)
        faces += [(f, obj.texture) for f in _faces(obj)]
    zb = float(scene.background_depth)
    if not math.isfinite(zb) or zb - hi[2] <= 0.1:
        raise SimError(f"scene background_depth: expected more than 0.1 m beyond the camera's farthest z "
                       f"({hi[2]:.3g} m), got {zb!r}")
    # The background covers every ray that can reach it, with 10 % margin.
    left, right, top, bottom = fov
    reach = zb - lo[2]
    x0, x1 = lo[0] + min(left, 0) * reach, hi[0] + max(right, 0) * reach
    y0, y1 = lo[1] + min(top, 0) * reach, hi[1] + max(bottom, 0) * reach
    pad_x, pad_y = 0.1 * (x1 - x0) + 0.01, 0.1 * (y1 - y0) + 0.01
    faces.append((("background", np.array([(x0 + x1) / 2, (y0 + y1) / 2, zb]), np.array([1.0, 0, 0]),
                   np.array([0, 1.0, 0]), ((x1 - x0) / 2 + pad_x, (y1 - y0) / 2 + pad_y), False), scene.background))

    images, rows = [], []
    min_z = math.inf
    for k, ((name, center, u, v, (hu, hv), one_sided), texture) in enumerate(faces):
        n = np.cross(u, v)
        corners = [center + su * hu * u + sv * hv * v for su in (-1, 1) for sv in (-1, 1)]
        min_z = min(min_z, min(c[2] for c in corners))
        distance = max(float(np.linalg.norm(center - mean_cam)), 0.05)
        texel = max(distance / focal, 2 * max(hu, hv) / MAX_TEXELS)
        rng = np.random.default_rng([seed, 7919, k])
        image = make_texture(texture, (2 * hu, 2 * hv), texel, rng)
        shade = AMBIENT + (1 - AMBIENT) * abs(float(n @ LIGHT))
        images.append(image)
        rows.append((center, u, v, n, (hu, hv), one_sided, shade, texel, image.shape, name))
    offsets = np.cumsum([0] + [im.size for im in images[:-1]])
    return PackedScene(
        centers=np.array([r[0] for r in rows]), axes_u=np.array([r[1] for r in rows]),
        axes_v=np.array([r[2] for r in rows]), normals=np.array([r[3] for r in rows]),
        half=np.array([r[4] for r in rows], dtype=np.float64), one_sided=np.array([r[5] for r in rows], dtype=np.uint8),
        shade=np.array([r[6] for r in rows]), texel=np.array([r[7] for r in rows]),
        tex_offset=offsets.astype(np.int64), tex_shape=np.array([r[8] for r in rows], dtype=np.int64),
        tex_flat=np.concatenate([im.ravel() for im in images]).astype(np.float32),
        names=[r[9] for r in rows], min_z=float(min_z))
