"""Dense depth maps per time window, with an age map, as ``.npy`` and 16-bit PNG.

Window ``k`` covers ``[t0 + k W, t0 + (k+1) W)`` µs. Each pixel shows its latest estimate
made before the window's end and at most ``max_age`` old (default ``W``: only this
window's estimates); the age map gives, in milliseconds, how long before the window's
end that estimate was made. Pixels without one are NaN. A window whose map would hold no
depth at all is not written (its number is skipped), and at most ``tofnet.units.MAX_MAPS``
maps are: more is one line before the first is written.

PNG: single-channel 16-bit greyscale, depth in whole millimetres (rounded to nearest),
0 = no depth, depths above 65.535 m written as 65535 (counted). Written with Pillow,
which tofnet already has through matplotlib; no new dependency.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tofnet.errors import DataError

#: Largest depth a 16-bit millimetre PNG holds, m.
PNG_MAX_DEPTH = 65.535
#: A 2-D float32 ``.npy``'s header (numpy pads it to 128 bytes); an ``index.csv`` row, at most.
NPY_HEADER_BYTES, INDEX_ROW_BYTES = 128, 96


@dataclass
class DepthMap:
    """One window: ``depth`` (H, W) float32 m and ``age_ms`` (H, W) float32, NaN where none."""

    index: int
    t_start_us: int
    t_end_us: int
    depth: np.ndarray
    age_ms: np.ndarray
    estimates: int  # estimates made in this window


class DepthMaps:
    """The maps ``depth_maps`` makes, one by one when iterated; how many (``windows``) and their ``size``
    (W, H px) are known before the first is made."""

    def __init__(self, maps: Iterator[DepthMap], windows: int, size: tuple[int, int]):
        self._maps, self.windows, self.size = maps, windows, size

    def __iter__(self) -> Iterator[DepthMap]:
        return self._maps

    def map_bytes(self, *, age: bool = True, png: bool = True) -> int:
        """The bytes ``write_depth_maps`` writes per map, at most: its float32 ``.npy`` (and the age map's)
        exactly, its PNG at its uncompressed size plus zlib's and PNG's overhead (it compresses, often
        much: sparse maps are mostly 0), its ``index.csv`` row."""
        width, height = self.size
        raw_png = height * (2 * width + 1)  # a filter byte per row of 16-bit pixels
        return ((1 + age) * (NPY_HEADER_BYTES + 4 * width * height) + INDEX_ROW_BYTES
                + (raw_png + raw_png // 1000 + 1024 if png else 0))


def depth_maps(depth: np.ndarray, sensor_size: tuple[int, int], window_us: int, *, t0_us: int | None = None,
               max_age_us: int | None = None, source: str = "depth") -> DepthMaps:
    """``DepthMap`` per window holding depth, from ``DEPTH_DTYPE`` estimates sorted by time (memory: two H x W
    maps). Windows without any (none made in the window, nor within ``max_age_us`` of its end) are skipped: an
    empty map says nothing, and a few estimates far apart in time would otherwise make millions of them. Checked
    before the first map (``source`` names the file in the one-line errors): at most ``MAX_MAPS`` maps."""
    from tofnet.units import MAX_MAPS, bounded_windows, format_seconds

    if window_us <= 0:
        raise DataError(f"window must be positive, got {window_us} µs")
    width, height = (int(v) for v in sensor_size)
    max_age_us = window_us if max_age_us is None else int(max_age_us)
    t = depth["t"]
    if len(t) and np.any(t[1:] < t[:-1]):
        raise DataError(f"{source}: depth estimates must be sorted by time")
    outside = (depth["x"] >= width) | (depth["y"] >= height)
    if np.any(outside):
        raise DataError(f"{source}: {int(outside.sum())} estimates lie outside the {width}x{height} map "
                        f"(first at x={int(depth['x'][outside][0])}, y={int(depth['y'][outside][0])})")
    if len(t) == 0:
        return DepthMaps(iter(()), 0, (width, height))
    t0 = int(t[0]) if t0_us is None else int(t0_us)
    if int(t[0]) < t0:  # window 0 starts at t0: these would be in no map
        raise DataError(f"{source}: estimates before t0_us = {t0}, where the maps start: "
                        f"{int(np.count_nonzero(t < t0)):,} (the first at {int(t[0])} µs)")
    runs = _windows_with_depth(t - t0, window_us, max_age_us)
    count = sum(stop - start for start, stop in runs)
    bounded_windows(count, window_us, f"{source}: the estimates ({format_seconds((int(t[-1]) - t0) * 1e-6)} after "
                    f"t0, each shown up to {format_seconds(max_age_us * 1e-6)})", "give a longer --window, a "
                    "shorter --max-age, or a time window (--start/--duration)", MAX_MAPS, "maps")
    return DepthMaps(_maps(depth, t0, (width, height), window_us, max_age_us, runs), count, (width, height))


def _windows_with_depth(rel_us: np.ndarray, window_us: int, max_age_us: int) -> list[tuple[int, int]]:
    """The windows ``[start, stop)`` (indices, merged runs) whose map holds depth: window ``k`` does when an
    estimate lies in ``[end_k - max_age, end_k)``, ``end_k = (k + 1) W``, i.e. ``k`` from ``rel // W`` to
    ``(rel + max_age) // W - 1`` (and up to the last estimate's window). One run per estimate at most."""
    last = int(rel_us[-1]) // window_us
    # An age beyond every window changes nothing; clipped, every sum below stays inside int64.
    age = min(max_age_us, (last + 1) * window_us)
    if age <= 0:
        return []
    first = rel_us // window_us
    final = np.minimum(first + (rel_us % window_us + age) // window_us - 1, last)
    keep = final >= first
    first, final = first[keep], final[keep]
    if len(first) == 0:
        return []
    # Both ends grow with time: a run starts where an estimate's windows begin after the previous one's end.
    new = np.ones(len(first), dtype=bool)
    new[1:] = first[1:] > final[:-1] + 1
    starts, ends = first[new], np.maximum.reduceat(final, np.flatnonzero(new))
    return [(int(a), int(b) + 1) for a, b in zip(starts, ends)]


def _maps(depth: np.ndarray, t0: int, size: tuple[int, int], window_us: int, max_age_us: int,
          runs: list[tuple[int, int]]) -> Iterator[DepthMap]:
    width, height = size
    t = depth["t"]
    latest_z = np.full(height * width, np.nan, dtype=np.float32)
    latest_t = np.zeros(height * width, dtype=np.int64)
    flat = depth["y"].astype(np.int64) * width + depth["x"]
    applied = 0
    for k in (k for start, stop in runs for k in range(start, stop)):
        t_end = t0 + (k + 1) * window_us
        begin, stop = (int(v) for v in np.searchsorted(t, [t_end - window_us, t_end], side="left"))
        if stop > applied:
            # The last estimate of each pixel before the window's end wins.
            reverse = flat[applied:stop][::-1]
            pixels, first = np.unique(reverse, return_index=True)
            last = stop - 1 - first
            latest_z[pixels] = depth["z"][last]
            latest_t[pixels] = t[last]
            applied = stop
        age_us = (t_end - latest_t).astype(np.float64)
        fresh = ~np.isnan(latest_z) & (age_us <= max_age_us)
        yield DepthMap(k, t_end - window_us, t_end,
                       np.where(fresh, latest_z, np.nan).reshape(height, width).astype(np.float32),
                       np.where(fresh, age_us * 1e-3, np.nan).reshape(height, width).astype(np.float32),
                       stop - begin)


def depth_to_png16(depth_m: np.ndarray) -> tuple[np.ndarray, int]:
    """Depth (m, NaN none) as uint16 millimetres (0 none); also how many pixels saturated at 65535."""
    valid = np.isfinite(depth_m) & (depth_m > 0)
    mm = np.zeros(depth_m.shape, dtype=np.uint16)
    values = np.floor(depth_m[valid] * 1000.0 + 0.5)
    saturated = int(np.count_nonzero(values > 65535))
    mm[valid] = np.clip(values, 1, 65535).astype(np.uint16)
    return mm, saturated


def write_png16(path: str | Path, image: np.ndarray) -> None:
    """A uint16 (H, W) array as a 16-bit greyscale PNG (written atomically, ``tofnet.io.files``)."""
    from PIL import Image

    from tofnet.io.files import atomic_write

    with atomic_write(path) as handle:
        Image.fromarray(np.ascontiguousarray(image, dtype=np.uint16)).save(handle, format="PNG")


def write_depth_maps(maps: Iterator[DepthMap], folder: str | Path, *, png: bool = True, age: bool = True) -> dict:
    """Write ``depth_<k>.npy`` (and ``age_<k>.npy``, ``depth_<k>.png``) per window and ``index.csv``.

    The folder is written as a whole (``tofnet.io.files.atomic_path``): it replaces an
    earlier export's folder, leaving exactly the new files, and never a folder holding
    files tofnet did not write there. ``index.csv``, one row per map written (windows without depth have none):
    ``window,t_start_s,t_end_s,pixels_with_depth,estimates_in_window``.
    Returns ``{"windows": n, "empty_windows": n, "saturated_png_pixels": n}`` (``empty_windows``: those
    before the last map that hold no depth, not written).
    """
    from tofnet.io.files import atomic_path, write_text_atomic
    from tofnet.io.npy import write_npy

    rows = ["window,t_start_s,t_end_s,pixels_with_depth,estimates_in_window"]
    saturated, spanned = 0, 0
    with atomic_path(folder, folder=True, written_by="tofnet export --maps") as partial:
        for depth_map in maps:
            spanned = depth_map.index + 1
            stem = f"{depth_map.index:06d}"
            write_npy(partial / f"depth_{stem}.npy", depth_map.depth)
            if age:
                write_npy(partial / f"age_{stem}.npy", depth_map.age_ms)
            if png:
                image, clipped = depth_to_png16(depth_map.depth)
                saturated += clipped
                write_png16(partial / f"depth_{stem}.png", image)
            pixels = int(np.count_nonzero(np.isfinite(depth_map.depth)))
            rows.append(f"{depth_map.index},{depth_map.t_start_us * 1e-6:.6f},{depth_map.t_end_us * 1e-6:.6f},"
                        f"{pixels},{depth_map.estimates}")
        write_text_atomic(partial / "index.csv", "\n".join(rows) + "\n")
    return {"windows": len(rows) - 1, "empty_windows": spanned - (len(rows) - 1), "saturated_png_pixels": saturated}
