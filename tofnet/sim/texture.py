"""Procedural textures for simulated surfaces: edges in every orientation, deterministic from a seed.

A texture is described by a small frozen ``Texture`` spec (plain data) and made into an
image of reflectances in ``(0, 1]`` by ``make_texture`` on a grid of square texels. The
image is smoothed with a Gaussian so that an edge spans one or two texels: the renderer
chooses the texel size so that one texel is about one image pixel at the surface's
nominal depth, which gives edges a pixel or two wide, as a real lens would.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from tofnet.sim.errors import SimError

#: Texture kinds ``make_texture`` knows.
KINDS = ("shapes", "checker", "edge", "stripes", "uniform")


@dataclass(frozen=True)
class Texture:
    """How a surface looks.

    Parameters
    ----------
    kind : one of ``KINDS``. ``shapes``: random rotated rectangles, discs, ellipses and
        convex polygons on a random background; ``checker``: a checkerboard at ``angle``;
        ``edge``: one straight edge through the centre, ``low`` on the side ``-normal``
        and ``high`` on the side ``+normal`` where ``normal = (cos angle, sin angle)`` in
        texture coordinates (``a`` along the surface's u axis, ``b`` along its v axis);
        ``stripes``: a square wave across ``normal``; ``uniform``: ``high`` everywhere.
    scale : feature size in metres: shape size, checker square, stripe half-period.
    levels : ``(low, high)`` reflectances in ``(0, 1]``; shapes draw their grey levels
        uniformly in between.
    angle : radians; ``None`` draws it from the seed (``checker``, ``stripes``) or uses 0.
    coverage : ``shapes`` only: expected number of shapes covering a point.
    blur : Gaussian sigma of the smoothing, in texels.
    """

    kind: str = "shapes"
    scale: float = 0.05
    levels: tuple[float, float] = (0.2, 0.8)
    angle: float | None = None
    coverage: float = 1.0
    blur: float = 0.7

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise SimError(f"texture kind: expected one of {', '.join(KINDS)}, got {self.kind!r}")
        if not self.scale > 0:
            raise SimError(f"texture scale: expected a positive size in metres, got {self.scale!r}")
        low, high = self.levels
        if not 0 < low <= 1 or not 0 < high <= 1:
            raise SimError(f"texture levels: expected two reflectances in (0, 1], got {self.levels!r}")
        if self.blur < 0 or self.coverage < 0:
            raise SimError(f"texture blur/coverage: expected non-negative numbers, got {self.blur!r}/{self.coverage!r}")


def make_texture(spec: Texture, size: tuple[float, float], texel: float, rng: np.random.Generator) -> np.ndarray:
    """Render ``spec`` onto a surface of ``size = (width, height)`` metres.

    Parameters
    ----------
    spec : the texture.
    size : surface extent along its u and v axes, metres.
    texel : texel edge length, metres.
    rng : source of every random choice (shapes, levels, angles).

    Returns
    -------
    float32 array ``(rows, cols)``: texel ``[i, j]`` is centred at
    ``a = (j + 0.5) * texel - width/2``, ``b = (i + 0.5) * texel - height/2``.
    """
    cols = max(2, int(math.ceil(size[0] / texel)))
    rows = max(2, int(math.ceil(size[1] / texel)))
    a = (np.arange(cols) + 0.5) * texel - cols * texel / 2
    b = (np.arange(rows) + 0.5) * texel - rows * texel / 2
    low, high = spec.levels
    angle = spec.angle if spec.angle is not None else (rng.uniform(0, math.pi) if spec.kind in ("checker", "stripes")
                                                        else 0.0)
    ca, sa = math.cos(angle), math.sin(angle)
    if spec.kind == "uniform":
        image = np.full((rows, cols), high)
    elif spec.kind == "edge":
        across = a[None, :] * ca + b[:, None] * sa
        image = np.where(across > 0, high, low)
    elif spec.kind == "stripes":
        across = a[None, :] * ca + b[:, None] * sa
        image = np.where(np.floor(across / spec.scale) % 2 == 0, high, low)
    elif spec.kind == "checker":
        # Random phase so squares do not line up across surfaces.
        a0, b0 = rng.uniform(0, spec.scale, size=2)
        along = a[None, :] * ca + b[:, None] * sa + a0
        across = -a[None, :] * sa + b[:, None] * ca + b0
        image = np.where((np.floor(along / spec.scale) + np.floor(across / spec.scale)) % 2 == 0, high, low)
    else:
        image = _shapes(spec, a, b, texel, rng)
    image = _blur(np.asarray(image, dtype=np.float64), spec.blur)
    return image.astype(np.float32)


def _shapes(spec: Texture, a: np.ndarray, b: np.ndarray, texel: float, rng: np.random.Generator) -> np.ndarray:
    """Random shapes, painted in order over a random background (painter's algorithm)."""
    low, high = spec.levels
    width, height = a.size * texel, b.size * texel
    background = rng.uniform(low, high)
    mean_area = (0.65 * spec.scale) ** 2
    n = int(rng.poisson(spec.coverage * width * height / mean_area))
    kind = rng.integers(0, 4, size=n)           # rectangle, disc, ellipse, convex polygon
    size = spec.scale * rng.uniform(0.3, 1.0, size=n)  # circumradius-like, m
    centre = rng.uniform([-width / 2, -height / 2], [width / 2, height / 2], size=(n, 2))
    level = rng.uniform(low, high, size=n)
    theta = rng.uniform(0, math.pi, size=n)
    aspect = rng.uniform(0.3, 1.0, size=n)
    sides = rng.integers(3, 7, size=n)
    # Polygon vertices on a circle at sorted random angles: convex, counter-clockwise.
    phis = np.sort(rng.uniform(0, 2 * math.pi, size=(n, 6)), axis=1)
    image = np.full((b.size, a.size), background)
    _paint(image, a, b, kind, size, centre, level, theta, aspect, sides, phis)
    return image


@njit(cache=True)
def _paint(image, a, b, kind, size, centre, level, theta, aspect, sides, phis):  # pragma: no cover - numba
    """Paint each shape over ``image`` (texel centres ``a`` columns, ``b`` rows, ascending)."""
    vx = np.empty(6)
    vy = np.empty(6)
    for s in range(kind.shape[0]):
        r = size[s]
        j0 = np.searchsorted(a, centre[s, 0] - r)
        j1 = np.searchsorted(a, centre[s, 0] + r)
        i0 = np.searchsorted(b, centre[s, 1] - r)
        i1 = np.searchsorted(b, centre[s, 1] + r)
        c = math.cos(theta[s])
        sn = math.sin(theta[s])
        m = sides[s]
        for k in range(m):
            # Only the first ``m`` of the six sorted angles: still sorted, still convex.
            vx[k] = r * math.cos(phis[s, k])
            vy[k] = r * math.sin(phis[s, k])
        for i in range(i0, i1):
            for j in range(j0, j1):
                da = a[j] - centre[s, 0]
                db = b[i] - centre[s, 1]
                x = da * c + db * sn
                y = -da * sn + db * c
                if kind[s] == 0:
                    inside = abs(x) <= 0.7 * r and abs(y) <= 0.7 * r * aspect[s]
                elif kind[s] == 1:
                    inside = x * x + y * y <= (0.7 * r) ** 2
                elif kind[s] == 2:
                    inside = (x / r) ** 2 + (y / (r * aspect[s])) ** 2 <= 1.0
                else:
                    inside = True
                    for k in range(m):
                        k1 = (k + 1) % m
                        if (vx[k1] - vx[k]) * (y - vy[k]) - (vy[k1] - vy[k]) * (x - vx[k]) < 0:
                            inside = False
                            break
                if inside:
                    image[i, j] = level[s]


def _blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian blur with ``sigma`` texels; borders replicate the edge texel."""
    if sigma <= 0:
        return image
    radius = max(1, int(math.ceil(3 * sigma)))
    offsets = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 * (offsets / sigma) ** 2)
    kernel /= kernel.sum()
    for axis in (0, 1):
        padded = np.pad(image, [(radius, radius) if ax == axis else (0, 0) for ax in (0, 1)], mode="edge")
        out = np.zeros_like(image)
        n = image.shape[axis]
        for k, w in enumerate(kernel):
            out += w * (padded[k:k + n, :] if axis == 0 else padded[:, k:k + n])
        image = out
    return image
