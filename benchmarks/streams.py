"""Event streams for the speed benchmarks: synthetic at a chosen rate, and the simulator's scenes (cached).

Two synthetic kinds, both time-ordered and 1 s long unless asked otherwise:

- ``uniform``: every event at a uniformly random pixel and time, random polarity. No
  locality at all: the worst case for caches, and few pixels fire twice within a
  refractory period.
- ``edges``: a random texture (bands ``cell`` px wide with edges at random gaps of
  0.5-1.5 cells, half of them absent) moving diagonally at constant speed, so edge
  segments of both orientations sweep every pixel; each crossing fires a burst of
  ``burst`` events 150 µs apart (a real pixel fires several; the refractory filter
  keeps the first), with the speed chosen for the rate; plus ``noise`` of the rate as
  uniform background events. Locality like a real scene.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from numba import njit

from tofnet.events import EVENT_DTYPE, make_events
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording

#: Camera velocity (m/s) the synthetic streams are run with (the depths do not matter for speed).
SYNTHETIC_VELOCITY = (-0.5, 0.0, 0.1)
BURST_GAP_US = 150


def intrinsics_for(sensor: tuple[int, int]) -> Intrinsics:
    """A 200 px focal length (DAVIS240-like) centred on the sensor."""
    return Intrinsics(200.0, 200.0, (sensor[0] - 1) / 2, (sensor[1] - 1) / 2)


def _recording(events: np.ndarray, sensor: tuple[int, int]) -> Recording:
    return Recording(events, intrinsics=intrinsics_for(sensor), trajectory=ConstantVelocity(SYNTHETIC_VELOCITY),
                     sensor_size=sensor)


def uniform(sensor: tuple[int, int], rate: float, duration: float = 1.0, seed: int = 0) -> Recording:
    """``rate`` events/s at uniformly random pixels and times for ``duration`` s."""
    rng = np.random.default_rng(seed)
    n = int(rate * duration)
    t = np.sort(rng.integers(0, int(duration * 1e6), n))
    return _recording(make_events(t, rng.integers(0, sensor[0], n), rng.integers(0, sensor[1], n),
                                  rng.integers(0, 2, n)), sensor)


@njit(cache=True)
def _crossings(width, height, speed, cell, duration_us, first_band, bounds, polarity, burst,
               out_t, out_x, out_y, out_p):
    """Bursts where an edge of the texture (moving by ``speed`` px/s along +u and +v) passes a pixel.

    The texture is cut into bands ``cell`` px wide across each axis; band ``j`` has edges
    at the sorted positions ``bounds[axis, j - first_band]`` (random gaps), each with a
    ``polarity`` (-1: no edge there). So an edge is a segment one band long.
    """
    n = 0
    span = speed * duration_us * 1e-6  # texture travel during the stream, px
    for y in range(height):
        for x in range(width):
            for axis in range(2):
                a, b = (x, y) if axis == 0 else (y, x)  # a: along the crossing, b: across it
                for j in range(int(np.floor((b - span) / cell)), int(np.floor(b / cell)) + 1):
                    # the pixel is in band j while b - speed*t is in [j*cell, (j+1)*cell)
                    t_lo = max((b - (j + 1) * cell) / speed, 0.0)
                    t_hi = min((b - j * cell) / speed, duration_us * 1e-6)
                    # an edge at texture position e is crossed at t = (a - e) / speed
                    edges = bounds[axis, j - first_band]
                    lo = np.searchsorted(edges, a - speed * t_hi, side="right")
                    hi = np.searchsorted(edges, a - speed * t_lo, side="right")
                    for k in range(lo, hi):
                        p = polarity[axis, j - first_band, k]
                        if p < 0:
                            continue
                        t_us = int((a - edges[k]) / speed * 1e6)
                        for m in range(burst):
                            if t_us + m * BURST_GAP_US < duration_us:
                                out_t[n], out_x[n], out_y[n], out_p[n] = t_us + m * BURST_GAP_US, x, y, p
                                n += 1
    return n


def edges(sensor: tuple[int, int], rate: float, duration: float = 1.0, seed: int = 0, *, cell: int = 6,
          burst: int = 2, noise: float = 0.1) -> Recording:
    """``rate`` events/s of a cell texture moving diagonally (see the module doc), ``noise`` of them uniform."""
    width, height = sensor
    rng = np.random.default_rng(seed)
    # Each pixel sees 2 * speed/cell edge positions per second, half of them real edges.
    speed = rate * (1 - noise) * cell / (width * height * burst)
    span = speed * duration
    first_band, last_band = int(np.floor(-span / cell)) - 1, max(width, height) // cell + 1
    lo, hi = -span - 2 * cell, max(width, height) + 2 * cell
    count = int((hi - lo) / (0.5 * cell)) + 2  # gaps are 0.5-1.5 cells
    shape = (2, last_band - first_band + 1, count)
    bounds = lo + np.cumsum(rng.uniform(0.5 * cell, 1.5 * cell, shape), axis=2)
    polarity = np.where(rng.random(shape) < 0.5, -1, rng.integers(0, 2, shape)).astype(np.int8)
    capacity = int(width * height * 2 * (span / (0.5 * cell) + 4) * burst)
    out = np.empty(capacity, np.int64), np.empty(capacity, np.int64), np.empty(capacity, np.int64), \
        np.empty(capacity, np.uint8)
    n = _crossings(width, height, speed, cell, int(duration * 1e6), first_band, bounds, polarity, burst, *out)
    events = make_events(*(a[:n] for a in out))
    background = uniform(sensor, rate * noise, duration, seed + 1).events
    events = np.concatenate([events, background])
    return _recording(events[np.argsort(events["t"], kind="stable")], sensor)


def cache_dir() -> Path:
    """Where simulated scenes are kept between runs: ``$TOFNET_BENCH_CACHE`` or the temp folder."""
    path = Path(os.environ.get("TOFNET_BENCH_CACHE", Path(tempfile.gettempdir()) / "tofnet-bench"))
    path.mkdir(parents=True, exist_ok=True)
    return path


def scenario(name: str, duration: float, progress=print) -> Recording:
    """The simulator's scenario ``name`` (seed 0), simulated once and cached as its events."""
    from tofnet.sim import generate
    from tofnet.sim import scenario as config_of

    config = config_of(name, duration)
    path = cache_dir() / f"{name}-{duration:g}s-seed0.npy"
    if path.exists():
        events = np.load(path)
    else:
        progress(f"  simulating {name} ({duration:g} s) once; cached in {path}")
        events = generate(config, seed=0).events
        np.save(path, events)
    assert events.dtype == EVENT_DTYPE
    return Recording(events, intrinsics=config.intrinsics, trajectory=config.trajectory,
                     sensor_size=config.sensor_size)
