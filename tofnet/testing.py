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
              backend="reference", velocity=(-0.5, 0.0, 0.0), per: str = "pixel",
              intrinsics: Intrinsics = TEST_INTRINSICS, record_tot: bool = True, **tot_params) -> RunResult:
    """Run the paper's network on hand-placed spikes with the refractory filter off and t0 = 0.

    ``backend`` is a name or anything with ``run(compiled, recording, record_tot=...)``
    (e.g. a ``tofnet.conformance.BackendRunner``). ``tot_params`` go to the
    time-of-travel process (``distance``, ``counter_bits``); ``min_depth``/``max_depth``
    to the depth process.
    """
    depth_params = {k: tot_params.pop(k) for k in ("min_depth", "max_depth") if k in tot_params}
    net = depth_network(sensor_size, input={"refractory": 0, "t0": 0},
                        time_of_travel=tot_params, depth=depth_params,
                        velocity={"source": "constant", "velocity": list(velocity), "per": per})
    recording = Recording(step_events(spikes), intrinsics=intrinsics, sensor_size=sensor_size)
    return run_network(net, recording, backend=backend, record_tot=record_tot)


def run_network(network, recording: Recording, *, backend="reference", record_tot: bool = False) -> RunResult:
    """Compile ``network`` (automatic patches) and run it on ``backend`` (a name or a runner)."""
    from tofnet.compiler import compile_network

    runner = get_backend(backend) if isinstance(backend, str) else backend
    return runner.run(compile_network(network), recording, record_tot=record_tot)


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


def directed_edge(sensor_size: tuple[int, int], velocity_px_s: tuple[float, float], *, polarity=1,
                  start_us: int = 0, offset_px: float = 0.0) -> np.ndarray:
    """A straight edge whose normal is its velocity ``(vu, vv)`` px/s, in any direction.

    Each pixel fires one event when the edge reaches its centre: at
    ``start_us + (n . (x, y) - n_min + offset_px) / speed`` with ``n`` the unit normal,
    so diagonals are covered too. ``polarity`` is 0, 1, or a callable ``(x, y) -> p``
    array for polarity mixes. Events are sorted by time (ties: row-major pixel order).
    """
    width, height = sensor_size
    vu, vv = (float(v) for v in velocity_px_s)
    speed = float(np.hypot(vu, vv))
    if speed == 0:
        raise ValueError("directed_edge: the velocity must not be zero")
    y, x = np.mgrid[0:height, 0:width]
    along = (x * vu + y * vv) / speed
    t = start_us + np.round((along - along.min() + offset_px) / speed * 1e6).astype(np.int64)
    p = polarity(x, y) if callable(polarity) else np.full(x.shape, polarity)
    order = np.argsort(t.ravel(), kind="stable")
    return make_events(t.ravel()[order], x.ravel()[order], y.ravel()[order], np.asarray(p).ravel()[order])


def moving_pattern(sensor_size: tuple[int, int], velocity_px_s: tuple[float, float], duration_us: int, *,
                   kind: str = "blobs", scale_px: float = 4.0, seed: int = 0, sample_us: int = 250,
                   start_us: int = 0) -> np.ndarray:
    """Events of a binary texture translating across the sensor at ``velocity_px_s`` (px/s).

    The texture (``"blobs"``: random discs of radius about ``scale_px``; ``"checker"``:
    squares of side ``scale_px``) is sampled at every pixel centre every ``sample_us``;
    a pixel whose value changed fires one event at that sample time, ON (1) when it
    became bright. Gives edges in every orientation and both polarities.
    """
    width, height = sensor_size
    rng = np.random.default_rng(seed)
    times = np.arange(0, duration_us + 1, sample_us, dtype=np.int64)
    vu, vv = (float(v) for v in velocity_px_s)
    shift_u, shift_v = vu * times * 1e-6, vv * times * 1e-6
    # the texture point seen by pixel (x, y) at time t is (x - vu t, y - vv t)
    lo_u, lo_v = -shift_u.max() - 2, -shift_v.max() - 2
    hi_u, hi_v = width - shift_u.min() + 2, height - shift_v.min() + 2
    value = _texture(kind, (lo_u, hi_u, lo_v, hi_v), scale_px, rng)
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    previous = value(x - shift_u[0], y - shift_v[0])
    parts = []
    for t, su, sv in zip(times[1:], shift_u[1:], shift_v[1:]):
        current = value(x - su, y - sv)
        ey, ex = np.nonzero(current != previous)
        if len(ex):
            parts.append(make_events(np.full(len(ex), start_us + t), ex, ey, current[ey, ex] > previous[ey, ex]))
        previous = current
    return np.concatenate(parts) if parts else np.empty(0, dtype=EVENT_DTYPE)


def _texture(kind: str, bounds: tuple[float, float, float, float], scale_px: float, rng: np.random.Generator):
    """A binary texture over ``bounds`` ``(lo_u, hi_u, lo_v, hi_v)`` (px): ``value(a, b)`` at texture points."""
    lo_u, hi_u, lo_v, hi_v = bounds
    if kind == "checker":
        def value(a, b):
            return ((np.floor(a / scale_px) + np.floor(b / scale_px)) % 2).astype(np.int8)
    elif kind == "blobs":
        res = 4  # texture samples per pixel
        gu, gv = int((hi_u - lo_u) * res) + 1, int((hi_v - lo_v) * res) + 1
        n = max(1, int((hi_u - lo_u) * (hi_v - lo_v) / (np.pi * scale_px ** 2) * 0.6))
        cu, cv = rng.uniform(0, gu, n), rng.uniform(0, gv, n)
        radius = rng.uniform(0.5, 1.5, n) * scale_px * res
        image = np.zeros((gv, gu), dtype=np.int8)
        for u, v, r in zip(cu, cv, radius):
            a0, a1, b0, b1 = (int(max(0, u - r)), int(min(gu, u + r + 1)), int(max(0, v - r)), int(min(gv, v + r + 1)))
            bb, aa = np.mgrid[b0:b1, a0:a1]
            image[b0:b1, a0:a1] ^= ((aa - u) ** 2 + (bb - v) ** 2 <= r * r).astype(np.int8)

        def value(a, b):
            return image[np.clip(((b - lo_v) * res).astype(np.int64), 0, gv - 1),
                         np.clip(((a - lo_u) * res).astype(np.int64), 0, gu - 1)]
    else:
        raise ValueError(f"moving_pattern: unknown kind {kind!r}; expected 'blobs' or 'checker'")
    return value


# -- a turning camera (paper eq. 7) ---------------------------------------------------------------


def camera_flow(intrinsics: Intrinsics, depth_m: float, velocity, omega):
    """The image flow ``A t / Z + B ω`` (px/s) of a camera moving at ``velocity`` (m/s) and turning at
    ``omega`` (rad/s), both in the camera frame, for points at camera-frame depth ``depth_m``.

    Returns ``flow(u, v) -> (flow_u, flow_v)`` on arrays. A synthetic world in which every
    point keeps its depth: the flow does not change with time and eq. 7 holds exactly at
    every pixel (``tofnet.kernels.rotation`` has ``B ω``, ``tofnet.kernels.velocity`` ``A t``).
    """
    from tofnet.kernels.rotation import rotational_flow
    from tofnet.kernels.velocity import velocity_term

    k = intrinsics
    tx, ty, tz = (float(v) for v in velocity)
    wx, wy, wz = (float(w) for w in omega)

    def flow(u, v):
        at_u, at_v = velocity_term(tx, ty, tz, u, v, k.fx, k.fy, k.cx, k.cy)
        bw_u, bw_v = rotational_flow(wx, wy, wz, u, v, k.fx, k.fy, k.cx, k.cy)
        return at_u / depth_m + bw_u, at_v / depth_m + bw_v
    return flow


def flowing_pattern(sensor_size: tuple[int, int], flow, duration_us: int, *, kind: str = "blobs",
                    scale_px: float = 4.0, seed: int = 0, sample_us: int = 250, start_us: int = 0) -> np.ndarray:
    """Events of a binary texture carried by a stationary image flow ``flow(u, v)`` (px/s; ``camera_flow``).

    Like ``moving_pattern`` for a flow that varies across the image: the texture point pixel
    (x, y) sees at time ``t`` is where the flow, run backwards for ``t``, takes (x, y)
    (fourth-order Runge-Kutta, one step per ``sample_us``; the flow does not depend on time,
    so steps compose). A pixel whose value changed at a sample fires one event then.
    """
    width, height = sensor_size
    rng = np.random.default_rng(seed)
    n = duration_us // sample_us + 1
    h = -sample_us * 1e-6  # backwards
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    a, b = np.empty((n, height, width)), np.empty((n, height, width))
    a[0], b[0] = x, y
    for i in range(1, n):
        k1 = flow(a[i - 1], b[i - 1])
        k2 = flow(a[i - 1] + 0.5 * h * k1[0], b[i - 1] + 0.5 * h * k1[1])
        k3 = flow(a[i - 1] + 0.5 * h * k2[0], b[i - 1] + 0.5 * h * k2[1])
        k4 = flow(a[i - 1] + h * k3[0], b[i - 1] + h * k3[1])
        a[i] = a[i - 1] + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        b[i] = b[i - 1] + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    value = _texture(kind, (a.min() - 2, a.max() + 2, b.min() - 2, b.max() + 2), scale_px, rng)
    previous = value(a[0], b[0])
    parts = []
    for i in range(1, n):
        current = value(a[i], b[i])
        ey, ex = np.nonzero(current != previous)
        if len(ex):
            parts.append(make_events(np.full(len(ex), start_us + i * sample_us), ex, ey, current[ey, ex] > previous[ey, ex]))
        previous = current
    return np.concatenate(parts) if parts else np.empty(0, dtype=EVENT_DTYPE)


def turning_trajectory(velocity, omega, duration_s: float, rate_hz: float = 1000.0):
    """Ground-truth poses (a ``Trajectory``, as ``groundtruth.txt`` holds them) of a camera moving at a
    constant ``velocity`` (m/s) and turning at a constant ``omega`` (rad/s), both in the camera frame.

    The orientation is ``exp(t [ω]×)`` from the identity; the position integrates the
    world-frame velocity ``R(t) velocity`` (16 sub-steps per pose). Poses at ``rate_hz``
    from 0 to ``duration_s`` + one pose.
    """
    from tofnet.io.groundtruth import Trajectory, quaternion_to_matrix

    omega = np.asarray(omega, dtype=np.float64)
    rate = float(np.linalg.norm(omega))
    axis = omega / rate if rate > 0 else np.array([0.0, 0.0, 1.0])
    n = int(np.ceil(duration_s * rate_hz)) + 2
    fine = np.arange((n - 1) * 16 + 1) / (16 * rate_hz)
    half = 0.5 * rate * fine
    quaternions = np.column_stack([np.outer(np.sin(half), axis), np.cos(half)])
    world = quaternion_to_matrix(quaternions) @ np.asarray(velocity, dtype=np.float64)
    steps = 0.5 * (world[1:] + world[:-1]) * np.diff(fine)[:, None]
    positions = np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
    return Trajectory(fine[::16], positions[::16], quaternions[::16])


def noise_events(sensor_size: tuple[int, int], rate_hz_per_px: float, duration_us: int, *, seed: int = 0,
                 start_us: int = 0) -> np.ndarray:
    """Uniform background activity: Poisson events at ``rate_hz_per_px`` per pixel, random polarity."""
    width, height = sensor_size
    rng = np.random.default_rng(seed)
    n = rng.poisson(rate_hz_per_px * width * height * duration_us * 1e-6)
    t = np.sort(rng.integers(start_us, start_us + duration_us, n))
    return make_events(t, rng.integers(0, width, n), rng.integers(0, height, n), rng.integers(0, 2, n))


def merge_events(*parts: np.ndarray) -> np.ndarray:
    """One time-ordered event array from several (stable: ties keep argument order)."""
    events = np.concatenate([np.asarray(p, dtype=EVENT_DTYPE) for p in parts]) if parts else np.empty(0, EVENT_DTYPE)
    return events[np.argsort(events["t"], kind="stable")]


class LinearVelocity:
    """A camera velocity (m/s, camera frame) going linearly from ``start`` to ``end`` over
    ``duration_s`` seconds from t = 0, constant outside; a ``VelocitySource`` for
    ``Recording(trajectory=...)`` (velocity changes over time without a pose file)."""

    def __init__(self, start: tuple[float, float, float], end: tuple[float, float, float], duration_s: float):
        self.start = np.asarray(start, dtype=np.float64)
        self.end = np.asarray(end, dtype=np.float64)
        self.duration_s = float(duration_s)

    def velocity_at(self, t: np.ndarray) -> np.ndarray:
        share = np.clip(np.asarray(t, dtype=np.float64) / self.duration_s, 0.0, 1.0)[:, None]
        return self.start + share * (self.end - self.start)


# -- a process written as a user would write one: a declaration, a model, a registration -------
from tofnet.core.counters import Count  # noqa: E402
from tofnet.core.params import Param  # noqa: E402
from tofnet.core.ports import Payload, PortSpec  # noqa: E402
from tofnet.core.process import Process  # noqa: E402
from tofnet.core.vars import Var  # noqa: E402
from tofnet.models import StepModel, model  # noqa: E402


class ParityGateProcess(Process):
    """Passes the spikes of pixels with ``(x + y) % 2 == parity`` (a checkerboard mask).

    A stand-in for a user's own process in tests and the conformance suite: declared and
    registered through the public API only (``Process``, ``@model``), core-placed so that
    ``multiproc`` builds it on workers.
    """

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes"),)
    outports = (PortSpec("passed", Payload.POLARITY, 1, "the spikes of the chosen parity"),)
    params = (Param("parity", "int", 0, doc="0: pixels with x + y even; 1: odd", minimum=0, maximum=1),)
    counters = (Count("passed", "output", "spikes of the chosen parity sent on"),)
    resources_per_pixel = {"accumulators": 1, "neurons": 1}


@model(ParityGateProcess)  # one plain model for every family: integer logic, same on all backends
class ParityGateModel(StepModel):
    supports_regions = True  # it holds no per-pixel state: any region works

    def __init__(self, process, ctx):
        super().__init__(process, ctx)
        self.passed = 0

    def step(self, k, inbox):
        spikes = inbox.get("events")
        if spikes is None:
            return {"passed": None}
        keep = (spikes["x"].astype(np.int64) + spikes["y"]) % 2 == self.process.parity
        x0, x1, y0, y1 = self.ctx.bounds
        keep &= (spikes["x"] >= x0) & (spikes["x"] < x1) & (spikes["y"] >= y0) & (spikes["y"] < y1)
        self.passed += int(keep.sum())
        return {"passed": np.array(spikes[keep])}

    def counts(self):
        return {"passed": self.passed}


class HeartbeatProcess(Process):
    """Every step, events or not, a spike at each pixel (d, d) of the diagonal: a core-placed process
    that acts without input (a run must count exactly the steps it ran, on every backend and band)."""

    outports = (PortSpec("beat", Payload.POLARITY, 1, "a spike per diagonal pixel and step"),)
    counters = (Count("beats", "output", "spikes sent"),)
    resources_per_pixel = {"neurons": 1}


@model(HeartbeatProcess)
class HeartbeatModel(StepModel):
    supports_regions = True

    def __init__(self, process, ctx):
        super().__init__(process, ctx)
        self.beats = 0

    def step(self, k, inbox):
        x0, x1, y0, y1 = self.ctx.bounds
        diagonal = np.arange(max(x0, y0), min(x1, y1))
        out = np.zeros(len(diagonal), Payload.POLARITY.dtype)
        out["x"], out["y"] = diagonal, diagonal
        self.beats += len(out)
        return {"beat": out}

    def counts(self):
        return {"beats": self.beats}


class SpikeTallyProcess(Process):
    """Passes spikes until it has passed ``limit`` of them (0: no limit), keeping the tally: a
    process with a number of the whole process (a ``vector`` variable, so it runs whole on
    bands and workers) whose model reads its parameter from ``self.process`` each step."""

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes"),)
    outports = (PortSpec("passed", Payload.POLARITY, 1, "the spikes passed"),)
    params = (Param("limit", "int", 0, doc="spikes to pass at most (0: all)", minimum=0),)
    vars = (Var("tally", "vector", "int64", doc="spikes passed so far", settable=True, low=0),)
    counters = (Count("passed", "output", "spikes passed"),)
    resources_per_pixel = {"accumulators": 1}


@model(SpikeTallyProcess)
class SpikeTallyModel(StepModel):
    supports_regions = True  # it could emit per region, but its tally is the whole process's: it runs whole

    def __init__(self, process, ctx):
        super().__init__(process, ctx)
        self.tally = self.sent = 0

    def step(self, k, inbox):
        spikes = inbox.get("events")
        if spikes is None:
            return {"passed": None}
        room = len(spikes) if self.process.limit == 0 else max(0, self.process.limit - self.tally)
        passed = np.array(spikes[:room])
        self.tally += len(passed)
        self.sent += len(passed)
        return {"passed": passed}

    def counts(self):
        return {"passed": self.sent}

    def get_var(self, name, step):
        return np.array([self.tally])

    def set_var(self, name, value, step):
        self.tally = int(value[0])

    def set_param(self, name, value):
        pass  # read from self.process each step
