"""Small synthetic inputs for tests and the conformance suite (no simulator needed)."""

from __future__ import annotations

from typing import Iterable

import numpy as np

from tofnet.backends.base import RunResult
from tofnet.backends.registry import get_backend
from tofnet.events import EVENT_DTYPE, make_events
from tofnet.io.recording import Intrinsics, Recording
from tofnet.networks import depth_network

#: Intrinsics used by the hand-checkable cases: f = 200 px, principal point at 0.
TEST_INTRINSICS = Intrinsics(200.0, 200.0, 0.0, 0.0)


def step_events(spikes: Iterable[tuple[int, int, int, int]], timestep_us: int = 1000) -> np.ndarray:
    """Events from ``(step, x, y, polarity)`` tuples, each 100 µs into its step (t0 = 0)."""
    rows = sorted(spikes)
    if not rows:
        return np.empty(0, dtype=EVENT_DTYPE)
    steps, xs, ys, ps = (np.array(c) for c in zip(*rows))
    return make_events(steps * timestep_us + 100, xs, ys, ps)


def run_steps(spikes: Iterable[tuple[int, int, int, int]], sensor_size: tuple[int, int], *,
              backend: str = "reference", velocity=(-0.5, 0.0, 0.0), per: str = "pixel",
              intrinsics: Intrinsics = TEST_INTRINSICS, record_tot: bool = True, **tot_params) -> RunResult:
    """Run the paper's network on hand-placed spikes with the refractory filter off and t0 = 0.

    ``tot_params`` go to the time-of-travel process (``distance``, ``counter_bits``);
    ``min_depth``/``max_depth`` to the depth process.
    """
    depth_params = {k: tot_params.pop(k) for k in ("min_depth", "max_depth") if k in tot_params}
    net = depth_network(sensor_size, input={"refractory": 0, "t0": 0},
                        time_of_travel=tot_params, depth=depth_params,
                        velocity={"source": "constant", "velocity": list(velocity), "per": per})
    recording = Recording(step_events(spikes), intrinsics=intrinsics, sensor_size=sensor_size)
    return get_backend(backend).run(net, recording, record_tot=record_tot)


def moving_edge(sensor_size: tuple[int, int], speed_px_s: float, axis: str = "u", *, polarity: int = 1,
                start_us: int = 0) -> np.ndarray:
    """A straight edge crossing the sensor along ``axis`` ("u" or "v") at ``speed_px_s``.

    Negative speeds move towards -u / -v. Each pixel fires one event when the edge
    reaches its centre.
    """
    width, height = sensor_size
    along, across = (width, height) if axis == "u" else (height, width)
    position = np.arange(along) if speed_px_s > 0 else np.arange(along)[::-1]
    reach_us = start_us + np.round(np.arange(along) / abs(speed_px_s) * 1e6).astype(np.int64)
    t = np.repeat(reach_us, across)
    a = np.repeat(position, across)
    b = np.tile(np.arange(across), along)
    x, y = (a, b) if axis == "u" else (b, a)
    return make_events(t, x, y, np.full(t.shape, polarity))
