"""The float reference backend: the network executed step by step, literally.

Every process has a model with dense per-pixel state; every step each model reads
the messages its inputs were sent in the previous step (the one-step delay of every
connection) and runs the paper's per-step logic (Algorithm 1 for time-of-travel).
Slow on purpose: it is the readable statement of the semantics the fast backends
are checked against.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from tofnet.backends.base import REJECT_REASONS, Backend, ProgressCallback, RunResult, empty_counts
from tofnet.backends.runtime import as_pipeline, intrinsics_of, start_time_us, velocity_source_of, velocity_table
from tofnet.compiler.pipeline import PipelineParams
from tofnet.core.network import Network
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, DIRECTION_OFFSETS, TOT_DTYPE
from tofnet.io.recording import Recording
from tofnet.kernels.depth import EMITTED, classify, float_depth, signed_axis_count
from tofnet.kernels.input_filter import InputFilter
from tofnet.kernels.velocity import sample_grid, update_index, velocity_term
from tofnet.processes import DepthProcess, InputProcess, TimeOfTravelProcess, VelocityProcess

# A message is a tuple of arrays describing the graded spikes sent in one step
# (sparse: only active pixels), or None when the process sent nothing.


class InputModel:
    """Sends, in step k, the events the input filter accepted in step k: (x, y, polarity)."""

    def __init__(self, proc: InputProcess, pipeline: PipelineParams, recording: Recording, t0_us: int):
        self.filter = InputFilter(pipeline.sensor_size, t0_us, pipeline.timestep_us, pipeline.refractory_us,
                                  pipeline.refractory_per_polarity)
        steps, xs, ys, ps = self.filter.feed(recording.events)
        self.steps, self.xs, self.ys, self.ps = steps, xs, ys, ps
        self.bounds = np.searchsorted(steps, np.arange(0, (steps[-1] + 2) if len(steps) else 1))

    @property
    def last_step(self) -> int:
        return int(self.steps[-1]) if len(self.steps) else -1

    def step(self, k: int, inbox: dict) -> dict:
        if k + 1 >= len(self.bounds):
            return {"events": None}
        lo, hi = self.bounds[k], self.bounds[k + 1]
        if lo == hi:
            return {"events": None}
        return {"events": (self.xs[lo:hi], self.ys[lo:hi], self.ps[lo:hi])}


class TimeOfTravelModel:
    """Algorithm 1 on dense state: a counter and a stored polarity per unit."""

    def __init__(self, proc: TimeOfTravelProcess, pipeline: PipelineParams):
        width, height = pipeline.sensor_size
        self.distance = pipeline.distance
        self.counter_max = pipeline.counter_max
        self.counter = np.zeros((4, height, width), dtype=np.int64)
        self.polarity = np.zeros((4, height, width), dtype=np.int8)
        self.width, self.height = width, height

    def step(self, k: int, inbox: dict) -> dict:
        message = inbox.get("events")
        sent = None
        if message is not None:
            xs, ys, ps = message
            # 1. triggers: every unit of an active pixel with a running counter and the same polarity.
            counts = self.counter[:, ys, xs]
            fire = (counts > 0) & (self.polarity[:, ys, xs] == ps.astype(np.int8)[None, :])
            direction, index = np.nonzero(fire)
            sent = (xs[index], ys[index], direction, counts[direction, index])
            self.counter[direction, ys[index], xs[index]] = 0
        # 2. running counters advance; past the maximum they overflow to 0.
        running = self.counter > 0
        self.counter[running] += 1
        self.counter[self.counter > self.counter_max] = 0
        # 3. facilitation: the unit an edge moving along D reaches next, distance pixels on.
        if message is not None:
            for direction, (du, dv) in enumerate(DIRECTION_OFFSETS):
                tx = xs + du * self.distance
                ty = ys + dv * self.distance
                inside = (tx >= 0) & (tx < self.width) & (ty >= 0) & (ty < self.height)
                self.counter[direction, ty[inside], tx[inside]] = 1
                self.polarity[direction, ty[inside], tx[inside]] = ps[inside]
        return {"counts": sent if sent is not None and len(sent[0]) else None}


class VelocityModel:
    """Sends A t for every pixel in steps 0, U, 2U, ... (per pixel or at patch centres)."""

    def __init__(self, proc: VelocityProcess, pipeline: PipelineParams, recording: Recording, t0_us: int,
                 n_steps: int):
        intr = intrinsics_of(pipeline, recording)
        self.update_every = pipeline.update_every
        n_updates = update_index(n_steps, self.update_every) + 2
        self.table = velocity_table(velocity_source_of(pipeline, recording), t0_us, pipeline.timestep_us,
                                    self.update_every, n_updates)
        width, height = pipeline.sensor_size
        self.u, self.v = sample_grid(pipeline.velocity_per == "pixel", pipeline.velocity_patch_size, width, height)
        self.intrinsics = (intr.fx, intr.fy, intr.cx, intr.cy)

    def step(self, k: int, inbox: dict) -> dict:
        if k % self.update_every:
            return {"a_t": None}
        tx, ty, tz = self.table[k // self.update_every]
        at_x, at_y = velocity_term(tx, ty, tz, self.u, self.v, *self.intrinsics)
        return {"a_t": (at_x, at_y)}


@njit(cache=True)
def _depth_neuron(counts, at_x, at_y, seconds_per_count, min_depth, max_depth, out_z, out_reason):
    for i in range(counts.shape[1]):
        sx = signed_axis_count(counts[0, i], counts[1, i])
        sy = signed_axis_count(counts[2, i], counts[3, i])
        z = float_depth(sx, sy, at_x[i], at_y[i], seconds_per_count)
        out_z[i] = z
        out_reason[i] = classify(sx != 0 or sy != 0, z, min_depth, max_depth)


class DepthModel:
    """Holds the latest A t; turns the counters that arrived into a depth (paper eq. 8)."""

    def __init__(self, proc: DepthProcess, pipeline: PipelineParams):
        width, height = pipeline.sensor_size
        self.at_x = np.zeros((height, width))
        self.at_y = np.zeros((height, width))
        self.seconds_per_count = pipeline.timestep / pipeline.distance
        self.min_depth, self.max_depth = pipeline.min_depth, pipeline.max_depth
        self.rejected = empty_counts(REJECT_REASONS)
        self.width = width

    def step(self, k: int, inbox: dict) -> dict:
        velocity = inbox.get("a_t")
        if velocity is not None:  # applied before this step's counters
            self.at_x, self.at_y = velocity
        message = inbox.get("counts")
        if message is None:
            return {"depth": None}
        xs, ys, direction, values = message
        pixel = ys * self.width + xs
        pixels, slot = np.unique(pixel, return_inverse=True)
        counts = np.zeros((4, len(pixels)), dtype=np.int64)
        counts[direction, slot] = values
        px, py = pixels % self.width, pixels // self.width
        z = np.empty(len(pixels))
        reason = np.empty(len(pixels), dtype=np.int64)
        _depth_neuron(counts, self.at_x[py, px], self.at_y[py, px], self.seconds_per_count,
                      self.min_depth, self.max_depth, z, reason)
        for code, name in enumerate(REJECT_REASONS):
            self.rejected[name] += int(np.count_nonzero(reason == code))
        keep = reason == EMITTED
        return {"depth": (px[keep], py[keep], z[keep])}


class ReferenceBackend(Backend):
    """Step-by-step float execution of the process graph (the trusted reference)."""

    name = "reference"
    arithmetic = "float"

    def run(self, compiled, recording: Recording, *, record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        started = time.perf_counter()
        network: Network = getattr(compiled, "network", compiled)
        if not isinstance(network, Network):
            raise BackendError("the reference backend needs a Network or CompiledNetwork")
        pipeline = as_pipeline(compiled)
        t0_us = start_time_us(pipeline, recording)
        models = {}
        for proc in network.processes:
            if isinstance(proc, InputProcess):
                models[proc.name] = InputModel(proc, pipeline, recording, t0_us)
        input_model = models[pipeline.names[0]]
        n_steps = input_model.last_step + 1 + pipeline.latency_steps
        for proc in network.processes:
            if isinstance(proc, TimeOfTravelProcess):
                models[proc.name] = TimeOfTravelModel(proc, pipeline)
            elif isinstance(proc, DepthProcess):
                models[proc.name] = DepthModel(proc, pipeline)
            elif isinstance(proc, VelocityProcess):
                models[proc.name] = VelocityModel(proc, pipeline, recording, t0_us, n_steps)
            elif not isinstance(proc, InputProcess):
                raise BackendError(f"the reference backend has no model for {type(proc).__name__} ({proc.name})")
        order = [p.name for p in network.topological_order()]
        routes = [(src.process.name, src.name, dst.process.name, dst.name) for src, dst in network.connections()]
        outbox: dict[str, dict] = {name: {} for name in order}
        depth_parts, tot_parts = [], []
        tot_spikes = 0
        dt = pipeline.timestep_us
        for k in range(n_steps):
            inbox: dict[str, dict] = {name: {} for name in order}
            for src, src_port, dst, dst_port in routes:  # sent in step k-1, delivered now
                inbox[dst][dst_port] = outbox[src].get(src_port)
            outbox = {name: models[name].step(k, inbox[name]) for name in order}
            counts = outbox[pipeline.names[1]]["counts"]
            if counts is not None:
                tot_spikes += len(counts[0])
                if record_tot:
                    tot_parts.append(_tot_records(k, counts))
            depth = outbox[pipeline.names[2]]["depth"]
            if depth is not None and len(depth[0]):
                part = np.empty(len(depth[0]), dtype=DEPTH_DTYPE)
                part["x"], part["y"], part["z"] = depth
                part["step"] = k
                part["t"] = t0_us + (k + 1) * dt
                depth_parts.append(part)
            if progress is not None and k % 1000 == 0:
                progress(k, n_steps)
        flt = input_model.filter
        return RunResult(
            backend=self.name,
            depth=np.concatenate(depth_parts) if depth_parts else np.empty(0, DEPTH_DTYPE),
            events_in=flt.events_in, accepted=flt.accepted, dropped=flt.dropped,
            rejected=dict(models[pipeline.names[2]].rejected), tot_spikes=tot_spikes, steps=n_steps,
            t0_us=t0_us, timestep_us=dt, latency_steps=pipeline.latency_steps,
            wall_time=time.perf_counter() - started,
            tot=(np.concatenate(tot_parts) if tot_parts else np.empty(0, TOT_DTYPE)) if record_tot else None,
        )


def _tot_records(step: int, counts) -> np.ndarray:
    xs, ys, direction, values = counts
    out = np.empty(len(xs), dtype=TOT_DTYPE)
    out["step"], out["x"], out["y"], out["direction"], out["count"] = step, xs, ys, direction, values
    return out
