"""Showing a live depth map: a matplotlib window where there is a display, else PNGs written to a folder.

``DepthMap`` keeps the latest estimate of every pixel (m) and when it came; a view draws
the pixels estimated within the last ``keep_s`` seconds (of the source's clock), the
others blank. ``PngFolder`` writes ``depth-000001.png``, ``depth-000002.png``, ... every
``every_s`` seconds of wall time into a folder it is given (``tofnet live --out`` gives it a
temporary folder, ``tofnet.io.files.atomic_path``, put in place under ``--out`` when the run ends).
"""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

import numpy as np


class DepthMap:
    """Latest depth (m) and stamp (µs) per pixel of a ``width`` x ``height`` sensor."""

    def __init__(self, sensor_size: tuple[int, int], keep_s: float = 0.2, z_range: tuple[float, float] | None = None):
        width, height = sensor_size
        self.z = np.full((height, width), np.nan)
        self.t = np.full((height, width), np.iinfo(np.int64).min, dtype=np.int64)
        self.keep_us, self.z_range, self.latest_us = int(keep_s * 1e6), z_range, None

    def add(self, depth: np.ndarray) -> None:
        """Depth records (``t``, ``x``, ``y``, ``z``)."""
        self.z[depth["y"], depth["x"]] = depth["z"]
        self.t[depth["y"], depth["x"]] = depth["t"]
        self.latest_us = int(depth["t"].max()) if self.latest_us is None else max(self.latest_us, int(depth["t"].max()))

    def image(self) -> np.ndarray:
        """The depth of the pixels estimated within ``keep_s`` of the latest estimate; NaN elsewhere."""
        if self.latest_us is None:
            return np.full(self.z.shape, np.nan)
        return np.where(self.t >= self.latest_us - self.keep_us, self.z, np.nan)

    def limits(self) -> tuple[float, float]:
        """The colour range (m): ``z_range``, else the 5th-95th percentile of every pixel's latest depth."""
        return self.z_range if self.z_range is not None else percentile_limits(self.z)


def percentile_limits(z: np.ndarray) -> tuple[float, float]:
    """The 5th-95th percentile (m) of the finite values of ``z``; ``(0, 1)`` without any."""
    finite = z[np.isfinite(z)]
    if not len(finite):
        return 0.0, 1.0
    low, high = np.percentile(finite, [5, 95])
    return float(low), float(max(high, low + 1e-3))


class PngFolder:
    """A frame every ``every_s`` seconds of wall time into ``folder``.

    The depth map is copied where the packets are fed (a few ms at 1280x720) and encoded and
    written by a thread of its own, so a frame (about 30 ms at 1280x720) does not hold up the
    packets behind it: written in line, frames every 0.5 s took the p99 delay of a 1280x720
    replay from 5 to 107 ms. A frame due while the previous one is still being written is
    skipped (``skipped``): the view is a preview, the packets come first.

    ``folder`` is created when missing; nothing in it is removed (frames of the same numbers are
    replaced). ``shown_as``: the folder's name in ``close()``'s line (the final name of a temporary
    folder; default ``folder``)."""

    def __init__(self, folder: str | Path, depth: DepthMap, every_s: float = 0.5, shown_as: str | Path | None = None):
        from concurrent.futures import ThreadPoolExecutor
        self.folder = Path(folder)
        self.shown_as = Path(shown_as) if shown_as is not None else self.folder
        self.folder.mkdir(parents=True, exist_ok=True)
        self.depth, self.every_s, self.frames, self._next = depth, float(every_s), 0, time.perf_counter()
        self.skipped = 0
        self._palette = viridis_palette()  # matplotlib's colour map read once, not in the first frame
        self._writer = ThreadPoolExecutor(1, thread_name_prefix="tofnet-png")
        self._pending = None

    def tick(self, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now < self._next:
            return
        self._next = now + self.every_s
        if self._pending is not None and not self._pending.done():
            if not force:
                self.skipped += 1
                return
            self._pending.result()
        if self._pending is not None:
            self._pending.result()  # a frame that failed to be written: its error, here
        self.frames += 1
        final = self.folder / f"depth-{self.frames:06d}.png"
        depth = self.depth  # copies taken here; the percentiles (10-30 ms at 1280x720) and the PNG in the thread
        limits = tuple(depth.z_range) if depth.z_range is not None else depth.z.copy()
        self._pending = self._writer.submit(_write_frame, final, depth.image(), limits, self._palette)

    def stop(self) -> None:
        """End the writing thread (after the frame it is writing), with no last frame: the run failed
        or was interrupted. A frame whose writing failed is not there (``_write_frame``)."""
        self._writer.shutdown(wait=True)

    def summary(self) -> str:
        """``N PNG frames -> FOLDER`` (and how many were skipped)."""
        skipped = f" ({self.skipped} skipped: the previous one was still being written)" if self.skipped else ""
        return f"{self.frames} PNG frames -> {self.shown_as}{skipped}"

    def close(self) -> str:
        try:
            self.tick(force=True)
            self._pending.result()
        finally:
            self._writer.shutdown(wait=True)
        return self.summary()


def _write_frame(final: Path, z: np.ndarray, limits, palette: np.ndarray) -> None:
    """``limits``: ``(low, high)`` in m, or every pixel's latest depth to take them from."""
    low, high = limits if isinstance(limits, tuple) else percentile_limits(limits)
    temp = final.with_name(f".{final.name}.tmp")
    try:
        palette_png(temp, z, low, high, palette)
        os.replace(temp, final)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise


def viridis_palette() -> np.ndarray:
    """256 RGB colours: black (no depth), then viridis reversed (near = yellow)."""
    import matplotlib
    colours = (matplotlib.colormaps["viridis_r"](np.linspace(0, 1, 255))[:, :3] * 255).astype(np.uint8)
    return np.vstack([[[0, 0, 0]], colours]).astype(np.uint8)


def palette_png(path: Path, z: np.ndarray, low: float, high: float, palette: np.ndarray | None = None) -> None:
    """``z`` (m, NaN: none) as an 8-bit palette PNG: black where NaN, viridis (near = yellow) from ``low`` to
    ``high``. About 30 ms for 1280x720 (matplotlib's ``imsave`` takes 150 ms: too long between packets)."""
    from PIL import Image

    palette = viridis_palette() if palette is None else palette
    index = np.zeros(z.shape, np.uint8)
    known = np.isfinite(z)
    index[known] = 1 + np.clip((z[known] - low) / (high - low) * 254, 0, 254).astype(np.uint8)
    image = Image.fromarray(index)  # uint8: mode L, a palette turns it into P
    image.putpalette(palette.tobytes())
    image.save(path, format="PNG", compress_level=1)


def has_display() -> bool:
    """A window can be opened: a display is set and matplotlib's backend is interactive."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) and os.name != "nt":
        return False
    import matplotlib
    return matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo", "template")


class Window:
    """A matplotlib window redrawn about ``fps`` times a second."""

    def __init__(self, depth: DepthMap, fps: float = 10.0, title: str = "tofnet live"):
        import matplotlib.pyplot as plt

        self.plt, self.depth, self.every_s, self._next = plt, depth, 1.0 / fps, time.perf_counter()
        plt.ion()
        self.figure, axes = plt.subplots()
        self.figure.canvas.manager.set_window_title(title)
        self.artist = axes.imshow(depth.image(), cmap="viridis_r")
        self.figure.colorbar(self.artist, ax=axes, label="depth (m)")

    def tick(self, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now < self._next:
            return
        self._next = now + self.every_s
        self.artist.set_data(self.depth.image())
        self.artist.set_clim(*self.depth.limits())
        self.figure.canvas.draw_idle()
        self.figure.canvas.flush_events()

    def close(self) -> str:
        self.tick(force=True)
        return "window"
