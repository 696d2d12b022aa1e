"""The ``multiproc`` backend: the compiled mapping run with one OS process per group of cores.

Each worker (``tofnet.backends._workers``) holds the event-driven kernel state of some
regions, a region being the pixels that one time-of-travel core and one depth core
share, so a pixel's counters and its depth neuron stay in one process. The host runs
the input filter and the velocity table, sends each worker exactly the spikes the
compiled mapping routes to its cores (``CoreAssignment.receives_mask``) in chunks of
many steps, and merges what comes back. The network is feed-forward, so a chunk of
many steps per synchronisation equals step-by-step execution; the integer results are
those of the ``fixed`` backend, bit for bit. Design, timeouts and cleanup: docs/backends.md.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from tofnet.backends._channel import Channel
from tofnet.backends.base import REJECT_REASONS, Backend, ProgressCallback, RunResult
from tofnet.backends.runtime import as_pipeline, intrinsics_of, start_time_us, velocity_source_of, velocity_table
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, TOT_DTYPE
from tofnet.io.recording import Recording
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS, FixedPointFormat
from tofnet.kernels.input_filter import InputFilter
from tofnet.kernels.region import KernelConfig, Region, velocity_rows

#: Seconds to wait for any one answer of a worker while running (a chunk, a start).
DEFAULT_TIMEOUT = 120.0
#: Seconds for the workers to start: spawn, import numpy/numba, load or compile the kernel.
DEFAULT_START_TIMEOUT = 300.0
#: Input steps per chunk: one synchronisation of host and workers per chunk.
DEFAULT_CHUNK_STEPS = 250
#: Chunks sent to a worker before the host waits for the oldest one's answer.
IN_FLIGHT = 2


@dataclass(frozen=True)
class WorkerPlan:
    """What one worker holds: regions (kernel states), the input rectangles each must receive
    (the halo of its time-of-travel core) and the global indices of the cores it runs."""

    index: int
    regions: tuple[Region, ...]
    halos: tuple[tuple[tuple[int, int, int, int], ...], ...]
    cores: tuple[int, ...]

    @property
    def pixels(self) -> int:
        return sum((r.x1 - r.x0) * (r.y1 - r.y0) for r in self.regions)


def compiled_of(compiled):
    """A ``CompiledNetwork``: ``compiled`` itself, or a ``Network`` compiled with default options."""
    if hasattr(compiled, "cores") and hasattr(compiled, "network"):
        return compiled
    from tofnet.compiler import compile_network
    from tofnet.core.network import Network
    if isinstance(compiled, Network):
        return compile_network(compiled)
    raise BackendError(f"the multiproc backend needs a CompiledNetwork or a Network, got {type(compiled).__name__}")


def plan_workers(compiled, workers: int) -> list[WorkerPlan]:
    """Split the compiled cores over at most ``workers`` processes.

    A region is the intersection of a time-of-travel core and a depth core (the same
    rectangle when both layers use one patch size); regions are dealt out in patch
    order (row by row) in contiguous, equal-sized groups so halos stay between
    neighbours. Workers that would get nothing are not planned.
    """
    pipeline = compiled.pipeline
    tot_cores = compiled.cores_of(pipeline.names[1])
    depth_cores = compiled.cores_of(pipeline.names[2])
    regions = []
    for tc in tot_cores:
        for dc in depth_cores:
            x0, y0, x1, y1 = max(tc.x0, dc.x0), max(tc.y0, dc.y0), min(tc.x1, dc.x1), min(tc.y1, dc.y1)
            if x0 < x1 and y0 < y1:
                regions.append((Region(x0, x1, y0, y1), tuple(tc.halo), (tc.index, dc.index)))
    n = max(1, min(int(workers), len(regions)))
    plans = []
    for index, group in enumerate(np.array_split(np.arange(len(regions)), n)):
        chosen = [regions[i] for i in group]
        cores = tuple(sorted({c for _, _, pair in chosen for c in pair}))
        plans.append(WorkerPlan(index, tuple(r for r, _, _ in chosen), tuple(h for _, h, _ in chosen), cores))
    return plans


def routing_table(plans: list[WorkerPlan], sensor_size: tuple[int, int]) -> np.ndarray:
    """``(workers, height, width)`` booleans: which workers an accepted spike at each pixel reaches."""
    from tofnet.compiler.partition import rects_mask
    width, height = sensor_size
    ys, xs = np.mgrid[0:height, 0:width]
    route = np.zeros((len(plans), height, width), dtype=bool)
    for plan in plans:
        for halo in plan.halos:
            route[plan.index] |= rects_mask(halo, xs, ys)
    return route


class MultiprocBackend(Backend):
    """Bit-exact integer execution with one spawned OS process per group of compiled cores.

    Parameters
    ----------
    workers
        Worker processes, at most one per region; default ``os.cpu_count()``.
    timeout
        Seconds to wait for any one answer of a worker; a ``BackendError`` names the worker.
    start_timeout
        Seconds for all workers to start (spawn, imports, numba cache load or compile).
    chunk_steps
        Input steps sent per synchronisation.
    frac_bits, payload_bits
        Fixed-point format, as for the ``fixed`` backend (docs/fixed_point.md).
    """

    name = "multiproc"
    arithmetic = "fixed"

    def __init__(self, workers: int | None = None, *, timeout: float = DEFAULT_TIMEOUT,
                 start_timeout: float = DEFAULT_START_TIMEOUT, chunk_steps: int = DEFAULT_CHUNK_STEPS,
                 frac_bits: int = DEFAULT_FRAC_BITS, payload_bits: int = DEFAULT_PAYLOAD_BITS):
        workers = (os.cpu_count() or 1) if workers is None else workers
        for label, value in (("workers", workers), ("chunk_steps", chunk_steps)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise BackendError(f"multiproc: {label} must be a positive whole number, got {value!r}")
        for label, value in (("timeout", timeout), ("start_timeout", start_timeout)):
            if not value > 0:
                raise BackendError(f"multiproc: {label} must be a positive number of seconds, got {value!r}")
        self.workers, self.timeout, self.start_timeout = workers, float(timeout), float(start_timeout)
        self.chunk_steps = chunk_steps
        self.format = FixedPointFormat(frac_bits, payload_bits)

    def session(self, compiled=None) -> "MultiprocSession":
        """Workers kept alive across runs: ``with backend.session(compiled) as s: s.run(recording)``.

        With ``compiled`` the session starts one worker per region up to ``workers``;
        without, ``workers`` workers, and each ``run`` names its network.
        """
        return MultiprocSession(self, None if compiled is None else compiled_of(compiled))

    def run(self, compiled, recording: Recording, *, record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        started = time.perf_counter()
        with self.session(compiled) as session:
            result = session.run(recording, record_tot=record_tot, progress=progress)
        result.wall_time = time.perf_counter() - started  # this run paid for starting the workers too
        return result


class MultiprocSession:
    """Running workers; a context manager that always stops them, on success, error or Ctrl-C.

    After any failure (a worker's exception, death or timeout) every worker is stopped
    and the session refuses further runs.
    """

    def __init__(self, backend: MultiprocBackend, compiled=None):
        self.backend = backend
        self.compiled = compiled
        self._channels: list[Channel] = []
        self._state = "new"
        #: Seconds the workers took to start (spawn + imports + kernel warm-up).
        self.startup_seconds = 0.0

    # -- lifetime ---------------------------------------------------------------------------
    def __enter__(self) -> "MultiprocSession":
        if self._state == "new":
            self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close(graceful=exc[0] is None)

    def open(self) -> None:
        """Spawn the workers and wait until each has its kernel ready."""
        if self._state != "new":
            raise BackendError(f"multiproc session is {self._state}; open a new one")
        started = time.perf_counter()
        n = self.backend.workers
        if self.compiled is not None:
            n = len(plan_workers(self.compiled, n))
        ctx = multiprocessing.get_context("spawn")  # never fork: no inherited threads, locks or fds
        self._state = "open"
        try:
            for index in range(n):
                self._channels.append(Channel(ctx, index))
            deadline = time.monotonic() + self.backend.start_timeout
            for channel in self._channels:
                channel.expect("ready", max(0.0, deadline - time.monotonic()), "starting",
                               timeout_name="start_timeout", limit=self.backend.start_timeout)
        except BaseException:
            self.close(graceful=False)
            raise
        self.startup_seconds = time.perf_counter() - started

    def close(self, graceful: bool = True) -> None:
        """Stop every worker and release its pipe and process handle (idempotent).

        ``graceful``: ask them to exit and wait; otherwise (after an error or Ctrl-C)
        terminate at once. Either way a worker still alive is killed.
        """
        channels, self._channels = self._channels, []
        if self._state != "failed":
            self._state = "closed"
        for channel in channels:
            channel.stop(graceful)
        for channel in channels:
            channel.release()

    @property
    def pids(self) -> list[int]:
        """Process ids of the running workers (for monitoring and the tests' fault hooks)."""
        return [c.process.pid for c in self._channels]

    def _inject_fault(self, worker: int, kind: str) -> None:
        """Test hook: make worker ``worker`` fail on its next chunk (``raise``, ``kill``, ``hang``)."""
        self._channels[worker].send(("fault", kind))

    # -- running ----------------------------------------------------------------------------
    def run(self, recording: Recording, *, compiled=None, record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        """Run ``compiled`` (default: the session's) on ``recording``; results sorted by step, y, x."""
        if self._state == "failed":
            raise BackendError("multiproc session failed earlier (a worker's error, death or timeout, or an "
                               "interrupt) and its workers were stopped; open a new session")
        if self._state != "open":
            raise BackendError(f"multiproc session is {self._state}; use it inside 'with backend.session(...)'")
        if compiled is None and self.compiled is None:
            raise BackendError("multiproc session: no network; pass compiled= to session() or run()")
        compiled = self.compiled if compiled is None else compiled_of(compiled)
        started = time.perf_counter()
        # Checks of the user's input come first: a bad recording must not cost the workers.
        pipeline = as_pipeline(compiled)
        config = KernelConfig.from_pipeline(pipeline, intrinsics_of(pipeline, recording), self.backend.format)
        config.check()
        source = velocity_source_of(pipeline, recording)
        try:
            return self._run(compiled, pipeline, config, source, recording, record_tot, progress, started)
        except BaseException:
            self._state = "failed"
            self.close(graceful=False)
            raise

    def _run(self, compiled, pipeline, config, source, recording, record_tot, progress, started) -> RunResult:
        backend = self.backend
        t0_us = start_time_us(pipeline, recording)
        plans = plan_workers(compiled, len(self._channels))
        route = routing_table(plans, pipeline.sensor_size)
        flt = InputFilter(pipeline.sensor_size, t0_us, pipeline.timestep_us, pipeline.refractory_us,
                          pipeline.refractory_per_polarity)
        steps, xs, ys, ps = flt.feed(recording.events)

        timeout = backend.timeout
        for plan in plans:
            self._channels[plan.index].send(("start", config, t0_us, plan.regions, plan.halos, record_tot))
        for plan in plans:
            self._channels[plan.index].expect("started", timeout, "starting a run")

        depth_parts, tot_parts, pending = [], [], deque()
        total, n = len(recording.events), len(steps)
        lo, seq = 0, 0
        while lo < n:
            hi = int(np.searchsorted(steps, steps[lo] + backend.chunk_steps, side="left"))
            first, count = velocity_rows(steps[lo:hi], pipeline.update_every)
            table = velocity_table(source, t0_us, pipeline.timestep_us, pipeline.update_every, count, first)
            cx, cy = xs[lo:hi], ys[lo:hi]
            sent = []
            for plan in plans:
                sel = route[plan.index][cy, cx]
                if sel.any():
                    self._channels[plan.index].send(("chunk", seq, steps[lo:hi][sel], cx[sel], cy[sel],
                                                     ps[lo:hi][sel], table, first))
                    sent.append(plan.index)
            pending.append((seq, sent))
            while len(pending) >= IN_FLIGHT:
                self._collect(*pending.popleft(), depth_parts, tot_parts)
            lo, seq = hi, seq + 1
            if progress is not None:
                progress(int(total * lo / n), total)
        while pending:
            self._collect(*pending.popleft(), depth_parts, tot_parts)

        rejected = np.zeros(len(REJECT_REASONS), dtype=np.int64)
        tot_spikes = 0
        for plan in plans:
            self._channels[plan.index].send(("finish",))
        for plan in plans:
            _, counts, spikes = self._channels[plan.index].expect("finished", timeout, "finishing a run")
            rejected += counts
            tot_spikes += int(spikes)
        if progress is not None:
            progress(total, total)
        fmt = backend.format
        return RunResult(
            backend=backend.name, depth=_depth(depth_parts),
            events_in=flt.events_in, accepted=flt.accepted, dropped=flt.dropped,
            rejected={reason: int(c) for reason, c in zip(REJECT_REASONS, rejected)},
            tot_spikes=tot_spikes, steps=(int(steps[-1]) if n else -1) + 1 + pipeline.latency_steps,
            t0_us=t0_us, timestep_us=pipeline.timestep_us, latency_steps=pipeline.latency_steps,
            wall_time=time.perf_counter() - started, tot=_tot(tot_parts) if record_tot else None,
            extra={"frac_bits": fmt.frac_bits, "payload_bits": fmt.payload_bits, "workers": len(plans),
                   "startup_s": self.startup_seconds})

    def _collect(self, seq: int, sent: list[int], depth_parts: list, tot_parts: list) -> None:
        for index in sent:
            reply = self._channels[index].expect("chunk", self.backend.timeout, f"running chunk {seq}")
            if reply[1] != seq:
                raise BackendError(f"multiproc worker {index} answered chunk {reply[1]} when chunk {seq} was due")
            if reply[2] is not None:
                depth_parts.append(reply[2])
            if reply[3] is not None:
                tot_parts.append(reply[3])


def _depth(parts: list) -> np.ndarray:
    """Estimates of every worker as one ``DEPTH_DTYPE`` array sorted by step, then y, then x."""
    if not parts:
        return np.empty(0, DEPTH_DTYPE)
    depth = np.concatenate(parts)
    return depth[np.lexsort((depth["x"], depth["y"], depth["step"]))]


def _tot(parts: list) -> np.ndarray:
    """Time-of-travel spikes sorted by step, y, x, direction."""
    if not parts:
        return np.empty(0, TOT_DTYPE)
    tot = np.concatenate(parts)
    return tot[np.lexsort((tot["direction"], tot["x"], tot["y"], tot["step"]))]
