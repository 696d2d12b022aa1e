"""What a recording declares that points at another clock, another unit or another camera: notes.

``check_metadata`` refuses what no file can mean (a focal length of 0); these are values a real file
can hold, but that usually come from a mistake which would otherwise give wrong depth without a sign
(docs/reliability.md, "Plausible"): poses whose times do not cover the events', a mean event rate
below one per second (times in µs read as seconds), event times all alike modulo 1000 µs with about
one event per time (ns of a µs clock read as µs), a principal point outside the sensor, every pose's
``qw`` near 0 (quaternions written w first). Each is one note, made once when a recording is
opened (``tofnet.io.source``), before a time window cuts the poses; those that rarely fit a correct file are
also the source's ``doubts``, which ``tofnet run`` says before it starts.
"""

from __future__ import annotations

import numpy as np

#: Poses covering less of the events' time span than this share are noted; less than ``LOUD_COVER``, said before a run.
POSE_COVER = 0.99
LOUD_COVER = 0.5
#: Poses further apart (median) than this many times the events' span (at least 1 s) are noted.
POSE_SPACING = 100.0
#: A mean rate below this (events/s) over more than ``MIN_EVENTS`` events is noted.
MIN_RATE = 1.0
MIN_EVENTS = 1000
#: Of the first events, at least this many distinct times all alike modulo 1000 µs, with fewer events per time than
#: ``MAX_PER_TIME``, are noted: a µs clock's times in ns (a clock of whole ms has many events per time).
MIN_TIMES = 100
MAX_PER_TIME = 4.0
#: Times from this on (read as µs: 3,170 years) are said before a run: ns since 1970 (ROS stamps, ``time_ns()``).
EPOCH_NS = 10**17


def plausibility_notes(source) -> list[tuple[str, str, bool]]:
    """``(topic, note, loud)`` for ``source`` (an ``EventSource``): ``topic`` ``poses``, ``times`` or ``camera``;
    ``loud`` when it usually means a mistake worth saying before a run. Decodes the first packet, for the first
    events' times (``EventSource.first_times``)."""
    first = source.first_time()
    if first is None:
        return []
    last = source._window_end_us()
    events = (first * 1e-6, None if last is None else last * 1e-6)
    found = [("poses", _poses_cover(source.trajectory, *events)), ("poses", _pose_spacing(source.trajectory, *events)),
             ("times", _event_rate(source.n_events, *events)), ("times", _time_grain(source.first_times(), *events)),
             ("camera", _principal_point(source)),
             ("poses", _quaternion_order(source.trajectory))]
    return [(topic, *said) for topic, said in found if said]


def _poses_cover(trajectory, first: float, last: float | None) -> tuple[str, bool] | None:
    times = getattr(trajectory, "times", None)
    if times is None or len(times) < 2:
        return None
    start, end = float(times[0]), float(times[-1])
    events = f"{first:.6f}..{last:.6f} s" if last is not None else f"from {first:.6f} s"
    if end < first or (last is not None and start > last):
        return (f"the poses ({start:.6f}..{end:.6f} s) do not overlap the events ({events}): every velocity is "
                "extrapolated from the nearest poses. Poses on another clock, or in other units? (seconds, on the "
                "events' clock; --velocity replaces them)", True)
    if last is None or last <= first:
        return None
    covered = (min(end, last) - max(start, first)) / (last - first)
    if covered < POSE_COVER:  # said before a run only when most of the events are outside (mocap starts late)
        return (f"the poses ({start:.6f}..{end:.6f} s) cover {100 * covered:.0f} % of the events' time span "
                f"({events}): outside it the velocity is extrapolated from the nearest poses", covered < LOUD_COVER)
    return None


def _pose_spacing(trajectory, first: float, last: float | None) -> tuple[str, bool] | None:
    times = getattr(trajectory, "times", None)
    if times is None or len(times) < 2 or last is None:
        return None
    spacing = float(np.median(np.diff(np.asarray(times, dtype=np.float64))))
    if spacing > POSE_SPACING * max(last - first, 1.0):  # µs read as seconds: a million times; sparse samples: not
        return (f"the poses are {spacing:g} s apart (median), against the events' {last - first:g} s: pose times "
                "in other units? (seconds)", True)
    return None


def _event_rate(n_events: int | None, first: float, last: float | None) -> tuple[str, bool] | None:
    if not n_events or n_events <= MIN_EVENTS or last is None or last <= first:
        return None
    rate = n_events / (last - first)
    if rate < MIN_RATE:
        return (f"{n_events:,} events over {last - first:g} s ({rate:.3g} events/s): times in other units? "
                "(text and float arrays hold seconds, integer arrays and binary formats µs)", True)
    return None


def _time_grain(times: np.ndarray, first: float, last: float | None) -> tuple[str, bool] | None:
    distinct = np.unique(times)
    if len(distinct) < MIN_TIMES or np.any(distinct % 1000 != distinct[0] % 1000):
        return None
    if len(times) / len(distinct) >= MAX_PER_TIME:  # a clock of whole ms with many events per tick: not a unit
        return None
    lasts = "" if last is None else f"; read as µs it lasts {last - first:.3g} s, in ns {(last - first) / 1000:.3g} s"
    # loud when the times are ns since 1970 (read as µs, thousands of years): a quiet sensor's ms clock is not
    return (f"the first {len(distinct):,} event times are all {distinct[0] % 1000} modulo 1000 µs, about one event "
            f"each: nanoseconds of a µs clock, or a clock of whole ms? (integer arrays and binary formats hold "
            f"µs{lasts})", bool(distinct[0] >= EPOCH_NS))


def _principal_point(source) -> tuple[str, bool] | None:
    note = principal_point_note(source.intrinsics, source.sensor_size)
    return (note, True) if note else None


def principal_point_note(intrinsics, size) -> str | None:
    """The note on a principal point outside the ``size`` (px) sensor, or None: made when a file is opened
    with the size it states, and by ``tofnet run``/``live`` with the size their network runs (a file that
    states none runs the default's)."""
    if intrinsics is None or size is None:
        return None
    width, height = size
    if not (0.0 <= intrinsics.cx <= width and 0.0 <= intrinsics.cy <= height):
        return (f"the principal point ({intrinsics.cx:g}, {intrinsics.cy:g}) px is outside the {width}x{height} "
                "sensor: the calibration of another camera or resolution, or a sensor size to give (--sensor-size)?")
    return None


def _quaternion_order(trajectory) -> tuple[str, bool] | None:
    quaternions = getattr(trajectory, "quaternions", None)
    if quaternions is None or len(quaternions) == 0:
        return None
    q = np.asarray(quaternions, dtype=np.float64)
    norms = np.linalg.norm(q, axis=1)
    if np.all(np.abs(q[:, 3]) < 0.1 * norms):
        return ("every pose's qw is near 0 (the camera turned half a turn from the world's axes throughout, as one "
                "looking straight down in a z-up world does): quaternions written w first? (the poses hold qx qy qz "
                "qw)", False)
    return None
