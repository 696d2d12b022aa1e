"""Ground-truth depth as frames: depth images or disparity maps at given times.

``FrameDepth`` holds the frame times (µs, the events' clock) and a way to read frame
``k`` as depth in metres (NaN where unknown: 0, NaN, inf or negative in the file). The
true depth at a time and pixel is the nearest frame's value (``interpolate=False``) or the
linear interpolation in time of the two frames around it (both must know the pixel);
a time further than ``max_gap_s`` from the frame used gets NaN. ``pixel_map`` (``(H, W, 2)``
float, DSEC's ``rectify_map``) takes a pixel of the events to the frames' pixel (rounded
to the nearest), for ground truth that lives in the rectified camera while the events do not.
Only the frames a query needs are read, each once per query.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located

#: A time further than this from the frame(s) used gets no ground truth (s).
MAX_FRAME_GAP_S = 0.1


class FrameDepth:
    """Depth frames ``(H, W)`` metres at increasing ``times_us``; see the module docstring."""

    def __init__(self, times_us: np.ndarray, read_frame: Callable[[int], np.ndarray], shape: tuple[int, int],
                 source: object, *, pixel_map: np.ndarray | None = None, max_gap_s: float = MAX_FRAME_GAP_S,
                 what: str = "depth images"):
        self.times_us = np.asarray(times_us, dtype=np.int64)
        self.read_frame, self.source, self.what = read_frame, source, what
        self.height, self.width = (int(v) for v in shape)
        self.pixel_map, self.max_gap_us = pixel_map, int(round(max_gap_s * 1e6))

    def __len__(self) -> int:
        return len(self.times_us)

    def span_us(self) -> tuple[int, int]:
        """First and last frame time (µs)."""
        return int(self.times_us[0]), int(self.times_us[-1])

    def frame(self, k: int) -> np.ndarray:
        """Frame ``k`` as float64 metres, NaN where unknown; ``DataError`` when its size is not the others'."""
        image = np.asarray(self.read_frame(int(k)), dtype=np.float64)
        if image.shape != (self.height, self.width):
            raise DataError(located(self.source, None, f"{self.what} frame {k} is {image.shape[1::-1]}, "
                                                       f"expected {self.width}x{self.height}"))
        image = image.copy()
        with np.errstate(invalid="ignore"):
            image[~np.isfinite(image) | (image <= 0)] = np.nan
        return image

    def pixels(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The frames' pixel of event pixels ``x``, ``y`` and which are inside the frames."""
        x, y = np.asarray(x, dtype=np.int64), np.asarray(y, dtype=np.int64)
        if self.pixel_map is not None:
            map_h, map_w = self.pixel_map.shape[:2]
            inside = (x >= 0) & (x < map_w) & (y >= 0) & (y < map_h)
            mapped = self.pixel_map[np.where(inside, y, 0), np.where(inside, x, 0)]
            with np.errstate(invalid="ignore"):
                fx, fy = np.round(mapped[:, 0]), np.round(mapped[:, 1])
                inside &= np.isfinite(fx) & np.isfinite(fy)
            x, y = np.where(inside, fx, -1).astype(np.int64), np.where(inside, fy, -1).astype(np.int64)
        inside = (x >= 0) & (x < self.width) & (y >= 0) & (y < self.height)
        return x, y, inside

    def at(self, t_us: np.ndarray, x: np.ndarray, y: np.ndarray, *, interpolate: bool = False) -> np.ndarray:
        """True depth (m, NaN unknown) at times ``t_us`` and event pixels ``x``, ``y``."""
        t = np.asarray(t_us, dtype=np.int64)
        out = np.full(len(t), np.nan)
        if len(t) == 0 or len(self.times_us) == 0:
            return out
        px, py, inside = self.pixels(x, y)
        last = len(self.times_us) - 1
        after = np.clip(np.searchsorted(self.times_us, t), 0, last)
        before = np.clip(np.searchsorted(self.times_us, t, side="right") - 1, 0, last)
        if interpolate:
            pairs = [(before, None), (after, None)]
            ok = inside & (np.abs(self.times_us[before] - t) <= self.max_gap_us) & \
                (np.abs(self.times_us[after] - t) <= self.max_gap_us)
        else:
            nearest = np.where(np.abs(self.times_us[before] - t) <= np.abs(self.times_us[after] - t), before, after)
            pairs = [(nearest, None)]
            ok = inside & (np.abs(self.times_us[nearest] - t) <= self.max_gap_us)
        values = [np.full(len(t), np.nan) for _ in pairs]
        for value, (index, _) in zip(values, pairs):
            for k in np.unique(index[ok]):
                pick = ok & (index == k)
                value[pick] = self.frame(int(k))[py[pick], px[pick]]
        if not interpolate:
            out[ok] = values[0][ok]
            return out
        span = (self.times_us[after] - self.times_us[before]).astype(np.float64)
        weight = np.where(span > 0, (t - self.times_us[before]) / np.where(span > 0, span, 1.0), 0.0)
        out[ok] = (values[0] * (1.0 - weight) + values[1] * weight)[ok]  # NaN unless both frames know the pixel
        return out

    def at_events(self, events: np.ndarray, *, interpolate: bool = False) -> np.ndarray:
        """True depth (m) of each event (``EVENT_DTYPE``), NaN where unknown."""
        return self.at(events["t"], events["x"], events["y"], interpolate=interpolate)


def png_size(path: Path, what: str = "PNG image", size: tuple[int, int] | None = None,
             whose: str = "") -> tuple[int, int]:
    """``(width, height)`` of a PNG from its header, without decoding it; checked as by ``read_png16``."""
    return _png(path, what, size, whose, decode=False)[0]


def read_png16(path: Path, size: tuple[int, int] | None = None, what: str = "PNG image",
               whose: str = "") -> np.ndarray:
    """A 16-bit (or 8-bit) grey PNG as an integer array ``(H, W)``; ``DataError`` naming the file otherwise.

    The file is opened as a regular file (``tofnet.io.files.open_regular``: a FIFO, device or folder
    is refused unread) and its header is checked before any pixel is decoded: the size must be
    ``size`` (``(width, height)``, ``whose`` size that is, for the message) when given and within the
    sensor limits (``MAX_SENSOR_PIXELS``)."""
    return _png(path, what, size, whose, decode=True)[1]


def _png(path: Path, what: str, size: tuple[int, int] | None, whose: str,
         decode: bool) -> tuple[tuple[int, int], np.ndarray | None]:
    import warnings

    from PIL import Image, UnidentifiedImageError

    from tofnet.events import sensor_size_problem
    from tofnet.io.files import open_regular

    with open_regular(path, what) as handle:
        try:
            with warnings.catch_warnings():  # PIL's DecompressionBombWarning: refused below all the same
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                image = Image.open(handle, formats=["PNG"])
            with image:
                width, height = image.size
                if size is not None and (width, height) != tuple(size):
                    raise DataError(located(path, None, f"{what} is {width}x{height} px, expected "
                                                        f"{size[0]}x{size[1]} px" + (f" ({whose})" if whose else "")))
                problem = sensor_size_problem(width, height)
                if problem:
                    raise DataError(located(path, None, f"{what}: {problem}"))
                if image.mode not in ("I;16", "I;16B", "I", "L"):
                    raise DataError(located(path, None, f"expected a grey 16-bit PNG (disparity x 256), got mode "
                                                        f"{image.mode}"))
                return (width, height), (np.asarray(image, dtype=np.int64) if decode else None)
        except UnidentifiedImageError:  # its message names the handle, not the file
            raise DataError(located(path, None, "not a PNG file")) from None
        except (OSError, ValueError, Image.DecompressionBombError) as err:
            raise DataError(located(path, None, f"not a readable PNG ({str(err).splitlines()[0][:120]})")) from None


def write_png16(path: Path, image: np.ndarray) -> None:
    """Write ``image`` (whole numbers 0..65535) as a 16-bit grey PNG (test fixtures, examples)."""
    from PIL import Image

    Image.fromarray(np.asarray(image, dtype=np.uint16)).save(path)


def disparity_to_depth(disparity_px: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Depth (m) of a disparity map (px, 0 = unknown) with OpenCV's reprojection matrix ``Q``.

    ``Q[2, 3]`` is the rectified focal length f (px) and ``1 / Q[3, 2]`` the baseline b (m),
    so depth = f * b / disparity (``Q[3, 3]`` corrects for different principal points), whichever
    sign the baseline was written with.
    """
    d = np.asarray(disparity_px, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = q[2, 3] / (q[3, 2] * d + q[3, 3])
    if q[2, 3] * q[3, 2] < 0:  # Q written for a baseline of the other sign (Tx > 0): depth is still f * b / d
        depth = -depth
    depth[~(d > 0) | ~np.isfinite(depth) | (depth <= 0)] = np.nan
    return depth


def check_overlap(source, frames, path: Path) -> None:
    """Ground-truth frames that are not in the events' time range belong to another sequence: a one-line error."""
    first = source.first_time()
    last = source._window_end_us()
    lo, hi = frames.span_us()
    if first is None or last is None:
        return
    if hi < first or lo > last:
        raise DataError(located(path, None, f"ground truth {lo * 1e-6:.6f}..{hi * 1e-6:.6f} s does not overlap "
                                            f"the events {first * 1e-6:.6f}..{last * 1e-6:.6f} s "
                                            f"({source.path.name}): the ground truth of another sequence?"))
