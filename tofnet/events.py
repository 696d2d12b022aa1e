"""In-memory layouts of event streams and depth estimates.

Events follow the event-camera ecosystem (tonic, aedat, Metavision): a numpy
structured array with ``t`` (int64, microseconds), ``x`` = column u and ``y`` = row v
(uint16, pixels) and ``p`` (uint8, 1 = ON, 0 = OFF).
"""

from __future__ import annotations

import numpy as np

from tofnet.errors import DataError

#: The documented time range: every time tofnet reads (events, poses, ``t0``) satisfies
#: ``|t| < MAX_TIME_US`` microseconds (2**61 µs, about 73,000 years), so differences and
#: sums of two times never overflow int64. Readers refuse times outside it.
MAX_TIME_US = 2**61

#: Largest sensor side in pixels (coordinates are uint16: 0..65535).
MAX_SENSOR_SIDE = 65536
#: Largest sensor in pixels: 2**24 (16.8 M, e.g. 4096x4096), 13x the largest event
#: sensors sold (1280x960). Bounds the memory and compile time one network needs.
MAX_SENSOR_PIXELS = 2**24

EVENT_DTYPE = np.dtype([("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])

#: Depth estimates: ``t`` stamp in microseconds (end of the output step), ``x``/``y``
#: pixel, ``z`` depth in metres, ``step`` the index of the output timestep.
DEPTH_DTYPE = np.dtype([("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("z", "<f8"), ("step", "<i8")])

#: Time-of-travel spikes: the step the unit fired in, its pixel, its direction
#: (index into ``DIRECTIONS``) and the counter value it sent (steps).
TOT_DTYPE = np.dtype([("step", "<i8"), ("x", "<u2"), ("y", "<u2"), ("direction", "u1"), ("count", "<i8")])

#: The four motion directions of a time-of-travel unit, in channel order.
#: Each is the (du, dv) pixel offset an edge moving in that direction makes per pixel.
DIRECTIONS = ("+u", "-u", "+v", "-v")
DIRECTION_OFFSETS = ((1, 0), (-1, 0), (0, 1), (0, -1))


def make_events(t_us, x, y, p) -> np.ndarray:
    """Build an event array from four sequences (``t`` in microseconds, ``p`` 0 or 1: another
    polarity, e.g. -1, is refused rather than cast to uint8)."""
    t_us = np.asarray(t_us)
    problem = polarity_problem(p)
    if problem:
        raise DataError(problem)
    events = np.empty(t_us.shape[0], dtype=EVENT_DTYPE)
    events["t"] = t_us
    events["x"] = np.asarray(x)
    events["y"] = np.asarray(y)
    events["p"] = np.asarray(p)
    return events


def polarity_problem(p) -> str | None:
    """Why polarities ``p`` are not all 0 (OFF) or 1 (ON), naming the first other value, or None.

    The one check of polarities taken as they are (the writers, ``make_events``, a stream's
    ``feed``); an event array's ``uint8`` column costs one ``max`` (~13 µs for 20,000 events).
    """
    p = np.asarray(p)
    if p.size == 0 or p.dtype.kind == "b" or (p.dtype.kind in "iu" and p.max() <= 1
                                               and (p.dtype.kind == "u" or p.min() >= 0)):
        return None
    p = p.ravel()
    bad = np.flatnonzero((p != 0) & (p != 1))
    return f"polarity must be 0 or 1, got {p[bad[0]]}" if bad.size else None


def sensor_size_problem(width: int, height: int) -> str | None:
    """Why ``width x height`` px is not an accepted sensor size, or None when it is."""
    if width < 1 or height < 1:
        return f"width and height must be positive, got {width}x{height}"
    if width > MAX_SENSOR_SIDE or height > MAX_SENSOR_SIDE:
        return f"each side must be at most {MAX_SENSOR_SIDE} px, got {width}x{height}"
    if width * height > MAX_SENSOR_PIXELS:
        return (f"at most {MAX_SENSOR_PIXELS:,} pixels (e.g. 4096x4096) are supported, got {width}x{height} = "
                f"{width * height:,}")
    return None
