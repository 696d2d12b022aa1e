"""The ``multiproc`` backend: the compiled mapping run with one OS process per group of cores.

Host-placed processes (input, velocity, ...) run in this process; every core-placed
process runs one model instance per compiled core, in worker processes
(``tofnet.backends.remote``), fed exactly the spikes the compiled mapping routes to
that core. The ``GraphExecutor`` drives both, a chunk of ``chunk_steps`` steps at a time
(the network is feed-forward, so chunks equal step-by-step execution); the results are
those of the ``fixed`` backend's models, bit for bit. Design, timeouts and cleanup:
docs/backends.md.
"""

from __future__ import annotations

import multiprocessing
import time
from typing import Iterable

import numpy as np

from tofnet.backends._channel import Channel, WorkersRefused, answers
from tofnet.backends.bands import resolve_workers, sampled_row_load
from tofnet.backends.base import Backend, ProgressCallback, RunResult, payloads_of
from tofnet.backends.graph import GraphExecutor, resolve_probes, sinks_of
from tofnet.backends.fusion import FusedStream, paper_chain
from tofnet.backends.local import binding, run_fused
from tofnet.backends.shared_bands import SharedBandKernel, band_rows, split_facts
from tofnet.backends.stream import packet_events_for
from tofnet.compiler.bands import input_reach
from tofnet.backends.remote import RemoteModel, plan_workers, placements_for
from tofnet.backends.runtime import clock_of, start_time_us
from tofnet.backends.stream import Collected, GraphStream
from tofnet.compiler.compiled import CompiledNetwork, network_of
from tofnet.kernels.compilation import Stopwatch
from tofnet.machine import cpu_count
from tofnet.errors import BackendError
from tofnet.io.recording import Intrinsics, Recording, VelocitySource
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS, FixedPointFormat

#: Seconds to wait for any one answer of a worker while running (a chunk, a start).
DEFAULT_TIMEOUT = 120.0
#: Steps per chunk: one synchronisation of host and workers per core-placed process and chunk.
DEFAULT_CHUNK_STEPS = 250
#: Steps per synchronisation at most: a chunk's steps run at once (1000 s at the 1 ms step).
MAX_CHUNK_STEPS = 1_000_000
#: Longest ``timeout``, ``start_timeout`` (s): a day; the waits overflow near 9.2e9 s (1e300 was an OverflowError).
MAX_TIMEOUT_S = 86_400.0
_REPLY = {"build": "built", "run": "run", "counts": "counts", "finish": "finished", "get": "get", "set": "set",
          "param": "param", "band": "band", "band_run": "band_run", "band_promise": "band_promise",
          "band_counts": "band_counts", "band_map": "band_map"}
#: Messages each worker answers on its own (no worker waits for another): a refusal is raised after the
#: others answered, so no pipe keeps a stale answer and the session stays usable when all refused alike.
_ANSWERED_ALONE = {"get", "set", "param", "counts"}


def compiled_of(compiled) -> CompiledNetwork:
    """A ``CompiledNetwork``: ``compiled`` itself, or a ``Network`` compiled with default options."""
    if isinstance(compiled, CompiledNetwork):
        return compiled
    from tofnet.compiler import compile_network
    return compile_network(network_of(compiled))


class MultiprocBackend(Backend):
    """Bit-exact integer execution with one spawned OS process per group of compiled cores.

    Parameters
    ----------
    workers
        Worker processes, at most one per core of the largest layer; default: the CPUs this process may use.
    timeout
        Seconds to wait for any one answer of a worker; a ``BackendError`` names the worker.
    start_timeout
        Seconds for all workers to start (spawn, imports, numba cache load or compile);
        default: ``timeout``, so one option bounds every wait.
    chunk_steps
        Steps run per synchronisation (per-core mode).
    per_core
        Run one model per compiled core, every spike through the host (the mapping, checked); by
        default the paper's chain runs each worker's cores as one band over shared memory.
    packet_events
        Events per packet of a banded run (None: 2^19 with several workers, 2^17 with one).
    frac_bits, payload_bits
        Fixed-point format, as for the ``fixed`` backend (docs/fixed_point.md).
    """

    capabilities = frozenset({"stream", "workers", "bands"})
    run_modes = (("bands", {}), ("per-core", {"per_core": True}))

    name = "multiproc"
    arithmetic = "fixed"
    family = "fixed"

    def __init__(self, workers: int | str | None = None, *, timeout: float = DEFAULT_TIMEOUT,
                 start_timeout: float | None = None, chunk_steps: int = DEFAULT_CHUNK_STEPS,
                 frac_bits: int = DEFAULT_FRAC_BITS, payload_bits: int = DEFAULT_PAYLOAD_BITS,
                 per_core: bool = False, packet_events: int | None = None):
        workers = cpu_count() if workers is None else resolve_workers(workers, "multiproc: workers")
        start_timeout = timeout if start_timeout is None else start_timeout
        for label, value in (("workers", workers), ("chunk_steps", chunk_steps)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise BackendError(f"multiproc: {label} must be a positive whole number, got {value!r}")
        if chunk_steps > MAX_CHUNK_STEPS:
            raise BackendError(f"multiproc: chunk_steps must be at most {MAX_CHUNK_STEPS} (steps run between two "
                               f"synchronisations, each held in memory), got {chunk_steps}")
        for label, value in (("timeout", timeout), ("start_timeout", start_timeout)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= MAX_TIMEOUT_S:
                raise BackendError(f"multiproc: {label} must be a positive number of seconds, at most "
                                   f"{MAX_TIMEOUT_S:g} (a day), got {value!r}")
        self.workers, self.timeout, self.start_timeout = workers, float(timeout), float(start_timeout)
        self.chunk_steps = chunk_steps
        self.format = FixedPointFormat(frac_bits, payload_bits)
        #: True: one model per compiled core, spikes through the pipes (checks the mapping); False: the
        #: paper's chain as one band per worker over shared memory (``shared_bands``), other graphs per core.
        self.per_core = bool(per_core)
        self.packet_events = packet_events_for(packet_events, workers, "multiproc")

    def session(self, compiled=None) -> "MultiprocSession":
        """Workers kept alive across runs: ``with backend.session(compiled) as s: s.run(recording)``.

        With ``compiled`` the session starts at most one worker per core of its largest layer,
        up to ``workers``; without, ``workers`` workers, and each ``run`` names its network.
        """
        return MultiprocSession(self, None if compiled is None else compiled_of(compiled))

    def run(self, compiled, recording: Recording, *, probes: Iterable[str] = (), record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        with self.session(compiled) as session:
            result = session.run(recording, probes=probes, record_tot=record_tot, progress=progress)
        result.setup_time += session.startup_seconds  # this run paid for starting the workers too
        return result

    def open_stream(self, compiled, **options) -> GraphStream | FusedStream:
        """A stream on workers of its own; ``close()`` stops them. Options as ``LocalBackend.open_stream``."""
        session = self.session(compiled)
        started = time.perf_counter()
        session.open()
        try:
            stream = session.open_stream(**{"fuse": True, **options})
        except BaseException:
            session.close(graceful=False)
            raise
        # starting the workers and building their bands, before the stream's clock began, is its set-up
        stream.clock.setup_before(max(0.0, stream.clock.started - started))
        if isinstance(stream, FusedStream):
            stream.releases.append(session.close)
        else:
            stream.on_close = lambda: session.close()
        return stream


class MultiprocSession:
    """Running workers; a context manager that always stops them, on success, error or Ctrl-C.

    After any failure (a worker's exception, death or timeout) every worker is stopped
    and the session refuses further runs.
    """

    #: A ``Session`` given one opens its streams on these workers (``Backend.capabilities``).
    capabilities = frozenset({"open session"})

    def __init__(self, backend: MultiprocBackend, compiled: CompiledNetwork | None = None):
        self.backend = backend
        self.compiled = compiled
        self._channels: list[Channel] = []
        self._state = "new"
        self._seq = 0
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
        """Spawn the workers and wait until each has its kernels ready."""
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
        """Test hook: make worker ``worker`` fail on its next ``run`` (``raise``, ``kill``, ``hang``)."""
        self._channels[worker].send(("fault", kind))

    # -- talking ----------------------------------------------------------------------------
    def _exchange(self, messages: dict[int, tuple], stuck=None, meanwhile=None) -> dict[int, tuple]:
        """Send each worker its message, call ``meanwhile()``, then take the answers as they come (all
        within ``timeout``): a worker's error is reported at once, even while another waits for it
        (their bands wait for each other in a packet). ``stuck()``: the workers to name first when
        none answers in time (e.g. those not waiting for the others)."""
        self._seq += 1
        for worker, message in messages.items():
            self._channels[worker].send(message)
        if meanwhile is not None:
            meanwhile()
        expected = {}
        for worker, message in messages.items():
            doing = f"running chunk {self._seq}" if message[0] in ("run", "band_run") else f"answering {message[0]!r}"
            expected[worker] = (self._channels[worker], _REPLY[message[0]], doing)
        kinds = {message[0] for message in messages.values()}
        if not kinds <= _ANSWERED_ALONE:
            return answers(expected, self.backend.timeout, stuck)
        try:
            return answers(expected, self.backend.timeout, stuck, settle=True)
        except WorkersRefused as err:
            if err.answered and kinds & {"set", "param"}:  # some workers changed their state, others did not
                self._state = "failed"
                self.close(graceful=False)
                raise BackendError(f"{err.refusal or err}; {err.answered} other worker(s) had applied it, so the "
                                   "session's state differed between workers and its workers were stopped") from None
            if err.refusal is not None:  # every worker refused the user's value, and nothing changed: as one model
                raise BackendError(err.refusal) from None
            raise

    def _exchange_quietly(self, kind: str) -> None:
        """Tell every worker ``kind`` (e.g. drop its band) when the session is still open."""
        if self._state == "open":
            self._guarded(lambda: self._exchange({w: (kind,) for w in range(len(self._channels))}))

    def _guarded(self, action):
        """Run ``action``; on any failure mark the session failed and stop the workers."""
        try:
            return action()
        except BaseException:
            self._state = "failed"
            self.close(graceful=False)
            raise

    # -- running ----------------------------------------------------------------------------
    def _check_open(self, compiled):
        if self._state == "failed":
            raise BackendError("multiproc session failed earlier (a worker's error, death or timeout, or an "
                               "interrupt) and its workers were stopped; open a new session")
        if self._state != "open":
            raise BackendError(f"multiproc session is {self._state}; use it inside 'with backend.session(...)'")
        if compiled is None and self.compiled is None:
            raise BackendError("multiproc session: no network; pass compiled= to session() or run()")
        return self.compiled if compiled is None else compiled_of(compiled)

    def open_stream(self, compiled=None, *, recording: Recording | None = None, intrinsics: Intrinsics | None = None,
                    velocity_source: VelocitySource | None = None, t0_us: int | None = None,
                    probes: Iterable[str] = (), record_tot: bool = False,
                    fuse: bool = False) -> GraphStream | FusedStream:
        """A ``GraphStream`` on this session's workers (see ``LocalBackend.open_stream``), model by model,
        one model per compiled core (as sessions need); ``fuse`` (unless the backend is ``per_core``):
        the paper's chain as one band per worker over shared memory (a ``FusedStream``)."""
        compiled = self._check_open(compiled)
        network = compiled.network
        known = binding(recording, intrinsics, velocity_source, network)
        clock = clock_of(network)
        probes = resolve_probes(network, probes, record_tot)
        sinks = sinks_of(network)
        # each worker's share of the cores balanced by the recording's events per row (as the threads' bands)
        plans = plan_workers(compiled, len(self._channels), sampled_row_load(known.events, network.sensor_size[1]))
        pipeline = None if self.backend.per_core or not fuse else paper_chain(network, "fixed", probes)
        if pipeline is not None:
            t0 = clock.t0_us if t0_us is None else int(t0_us)
            return self._banded_stream(compiled, pipeline, plans, known, t0, f"{pipeline.names[1]}.counts" in probes)

        facts = split_facts(compiled, plans)

        def build(start_us: int) -> GraphExecutor:
            specs: dict[int, list] = {plan.index: [] for plan in plans}

            def place(process, model_class, ctx):
                if process.placement != "core":
                    return model_class(process, ctx)
                placements, built = placements_for(compiled, process, model_class, plans, ctx)
                if placements[0].rect is None and process.name not in facts["whole"]:  # one instance, on one worker
                    facts["whole"].append(process.name)
                for placement, spec in zip(placements, built):
                    specs[placement.worker].append(spec)
                return RemoteModel(process, model_class, placements, self._exchange)

            from tofnet.backends.registry import backends_by_family
            executor = GraphExecutor(network, family=self.backend.family, backend=self.backend.name,
                                     t0_us=start_us, timestep_us=clock.timestep_us, recording=known,
                                     fixed_format=self.backend.format, probes=probes,
                                     backends_by_family=backends_by_family, place=place)
            # The user's input is checked above (models, bindings); only now do the workers work.
            self._guarded(lambda: self._exchange({w: ("build", s) for w, s in specs.items()}))
            return executor

        t0 = clock.t0_us if t0_us is None else int(t0_us)
        stream = _GuardedStream(self, self.backend.name, build, t0, clock.timestep_us, sinks,
                                payloads_of(network, list(dict.fromkeys(sinks + probes))))
        stream.extra = {"frac_bits": self.backend.format.frac_bits, "payload_bits": self.backend.format.payload_bits,
                        "startup_s": self.startup_seconds, **facts}
        return stream

    def _banded_stream(self, compiled, pipeline, plans, known, t0_us, record_tot: bool) -> FusedStream:
        """The paper's chain with each worker's share of the cores as one band (``shared_bands``)."""
        network = compiled.network
        source = pipeline.velocity_source(known)
        config = pipeline.kernel_config(known, self.backend.format)
        bands = band_rows(compiled, pipeline.names[1], plans)
        exchange = lambda m, *more: self._guarded(lambda: self._exchange(m, *more))  # noqa: E731
        kernel = self._guarded(lambda: SharedBandKernel(config, bands, input_reach(network), source, exchange,
                                                        t0_us or 0))
        kernel.facts["startup_s"] = self.startup_seconds
        return FusedStream(self.backend.name, config, pipeline, source, t0_us, record_tot,
                           order=[p.name for p in network.processes], kernel=kernel)

    def run(self, recording: Recording, *, compiled=None, probes: Iterable[str] = (), record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        """Run ``compiled`` (default: the session's) on ``recording``; outputs in canonical order."""
        compiled = self._check_open(compiled)
        clock = Stopwatch()
        t0 = start_time_us(clock_of(compiled.network).t0_us, recording)
        with clock.aside():  # the workers build their bands' state
            stream = self.open_stream(compiled, recording=recording, t0_us=t0, probes=probes, record_tot=record_tot,
                                      fuse=True)
        if isinstance(stream, FusedStream):
            try:
                result = run_fused(stream, recording.events, self.backend.packet_events, progress)
            except BaseException:
                stream.abort()  # its shared buffers
                raise
            self._exchange_quietly("finish")
            result.setup_time += clock.setup_seconds  # before the stream's own clock started
            return result
        collected = Collected()
        events, chunk_us = recording.events, self.backend.chunk_steps * stream.timestep_us
        total = len(events)
        chunk = np.maximum((events["t"] - t0) // chunk_us, -1)  # events before t0: one chunk
        bounds = np.flatnonzero(np.diff(chunk)) + 1
        for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, total]):
            if hi <= lo:
                continue
            # the last chunk runs to its last event's step, as a whole run does: a chunk's end past it would run
            # steps the run has not (a process that acts without input would count them)
            until = t0 + (int(chunk[hi - 1]) + 1) * chunk_us if hi < total else None
            collected.add(stream.feed_all(events[lo:hi], until_us=until))
            if progress is not None:
                progress(int(hi), total)
        result = stream.close()
        collected.add(result.outputs)
        result.outputs = collected.joined(result.payloads, stream._empty)
        return result.timed_by(clock)


class _GuardedStream(GraphStream):
    """A stream whose every step runs on the session's workers: a failure fails the session."""

    def __init__(self, session: MultiprocSession, *args):
        self.session = session
        self.on_close = None
        self.extra: dict = {}
        super().__init__(*args)

    def feed_all(self, events, until_us=None):
        self.check(events, until_us)  # a refused packet changes nothing: the workers go on
        return self.session._guarded(lambda: GraphStream.feed_all(self, events, until_us))

    def abort(self) -> None:
        """Stop the workers at once (the caller failed); the session is done."""
        GraphStream.abort(self)
        self.session._state = "failed"
        self.session.close(graceful=False)

    def close(self) -> RunResult:
        def finish() -> RunResult:
            result = GraphStream.close(self)
            executor = self.executor
            remote = {w for node in executor.nodes if isinstance(node.model, RemoteModel)
                      for w in (p.worker for p in node.model.placements)}
            self.session._exchange({w: ("finish",) for w in remote})
            return result
        try:
            result = self.session._guarded(finish)
        finally:
            if self.on_close is not None:
                with self.clock.aside():  # stopping the workers: not the network's time
                    self.on_close()
        result.setup_time = self.clock.setup_seconds
        result.extra.update(self.extra)
        return result
