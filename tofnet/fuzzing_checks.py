"""The documented rules a fuzz target's accepted result must satisfy (docs/reliability.md),
shared by every fuzz target module (``tofnet.fuzzing`` and its siblings)."""

from __future__ import annotations

import math

import numpy as np

from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE, MAX_TIME_US, sensor_size_problem

#: Longest error message accepted: a path plus the offending field, never a file's contents.
MAX_MESSAGE = 600


class Invalid(AssertionError):
    """An accepted result that breaks a documented rule."""


def require(condition: bool, rule: str) -> None:
    if not condition:
        raise Invalid(rule)


# ---------------------------------------------------------------- invariants

def check_events(events: np.ndarray) -> None:
    """Events as every reader must return them."""
    require(isinstance(events, np.ndarray) and events.dtype == EVENT_DTYPE, "events have EVENT_DTYPE")
    require(events.ndim == 1 and len(events) >= 1, "at least one event")
    t = events["t"]
    require(bool(np.all(np.abs(t) < MAX_TIME_US)), "|t| < 2**61 µs")
    require(bool(np.all(t[1:] >= t[:-1])), "times sorted")
    require(bool(np.all(events["p"] <= 1)), "polarity 0 or 1")


def check_recording(recording) -> None:
    """A recording: its events, and every side file it holds."""
    check_events(recording.events)
    if recording.intrinsics is not None:
        k = recording.intrinsics
        values = (k.fx, k.fy, k.cx, k.cy, *k.distortion)
        require(all(math.isfinite(v) for v in values) and k.fx > 0 and k.fy > 0, "finite intrinsics, fx, fy > 0")
    if recording.sensor_size is not None:
        require(sensor_size_problem(*recording.sensor_size) is None, "sensor size within the limits")
    if recording.gt_depth is not None:
        d = recording.gt_depth
        require(d.shape == (len(recording.events),), "one true depth per event")
        require(bool(np.all(np.isnan(d) | (np.isfinite(d) & (d > 0)))), "true depths NaN or finite > 0")
    if recording.imu is not None:
        require(recording.imu.ndim == 2 and recording.imu.shape[1] == 7 and bool(np.all(np.isfinite(recording.imu))),
                "IMU samples finite, 7 columns")
    if recording.trajectory is not None:
        check_velocity_source(recording.trajectory)


def check_velocity_source(source) -> None:
    times = source.times
    require(bool(np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)), "times finite and increasing")
    require(bool(np.all(np.abs(times) < MAX_TIME_US * 1e-6)), "times in range")
    probe = np.concatenate([times, [times[0] - 1.0, times[-1] + 1.0]])
    require(bool(np.all(np.isfinite(source.velocity_at(probe)))), "finite velocity everywhere")
    if hasattr(source, "quaternions"):
        norms = np.linalg.norm(source.quaternions, axis=1)
        require(bool(np.all(np.abs(norms - 1) < 1e-9)), "unit quaternions")


def check_depth(result) -> None:
    depth, meta = result
    require(depth.dtype == DEPTH_DTYPE and depth.ndim == 1, "DEPTH_DTYPE")
    require(bool(np.all(np.isfinite(depth["z"]))), "finite depths")
    require(bool(np.all(np.abs(depth["t"]) < MAX_TIME_US) and np.all(depth["step"] >= 0)), "t in range, step >= 0")
    require(set(meta) == {"t0_us", "timestep_us", "latency_steps", "summary"}, "meta keys")


def check_network(network) -> None:
    """A network whose every parameter is finite and within its declared range."""
    network.validate()
    for process in network.processes:
        for param in type(process).all_params():
            value = process.values[param.name]
            numbers = value if isinstance(value, tuple) else (value,)
            for number in numbers:
                if isinstance(number, (int, float)) and not isinstance(number, bool):
                    require(math.isfinite(number), f"{process.name}.{param.name} finite")
                    require(param.minimum is None or number >= param.minimum, f"{param.name} >= minimum")
                    require(param.maximum is None or number <= param.maximum, f"{param.name} <= maximum")
    require(sensor_size_problem(*network.sensor_size) is None, "sensor size within the limits")
