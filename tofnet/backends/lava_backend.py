"""The ``lava`` backend: any tofnet graph run as Lava processes (lava-nc 0.10, Python 3.10), step by step.

Each tofnet process becomes a Lava process running tofnet's model of the backend's family
(``fixed``: bit for bit what the ``fixed`` backend computes; ``arithmetic="float"``: the
``float`` models, tagged ``floating_pt``), with ``Loihi2SimCfg`` and ``RunSteps``
(``tofnet.backends.lava_processes``, docs/lava.md). ``LavaExecutor`` stands where the local
backends put a ``GraphExecutor``, so runs, streams and sessions work as they do there:
``Session.get/set`` of a variable are Lava's ``Var.get/set``.
"""

from __future__ import annotations

import atexit
import queue
import sys
import weakref
from typing import Any

import numpy as np

from tofnet.backends.graph import GraphExecutor
from tofnet.backends.local import LocalBackend
from tofnet.backends.stream import DEFAULT_PACKET_EVENTS
from tofnet.core.network import Network
from tofnet.errors import BackendError, UnsupportedError
from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Recording
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS, FixedPointFormat
from tofnet.models.base import concat

#: What to do when Lava cannot be imported here (one line, as every user error).
NEEDS_LAVA = ("the lava backend needs lava-nc 0.10, which runs on Python 3.10 only ({why}); make a venv: "
              "python3.10 -m venv ~/tofnet-lava && ~/tofnet-lava/bin/pip install 'tofnet[lava]' (docs/lava.md)")
#: Records a field port (one set of coefficients per update) may send in one step.
FIELD_RECORDS = 4
#: Seconds to wait for a sink's records after a run returned (they are already sent by then).
SINK_TIMEOUT_S = 60.0


def require_lava() -> None:
    """Raise one line saying how to get Lava when it cannot be imported in this interpreter."""
    if sys.version_info[:2] != (3, 10):
        raise BackendError(NEEDS_LAVA.format(why=f"this is Python {sys.version_info[0]}.{sys.version_info[1]}"))
    try:
        import lava.magma.core.process.process  # noqa: F401
    except ImportError as err:
        raise BackendError(NEEDS_LAVA.format(why=f"it is not installed: {err}")) from None


class LavaBackend(LocalBackend):
    """Runs any graph as Lava processes on Lava's CPU simulation of Loihi 2 (``Loihi2SimCfg``).

    ``arithmetic``: ``fixed`` (the ``fixed`` models, ``fixed_pt``; equal to the ``fixed``
    backend byte for byte) or ``float`` (``floating_pt``). ``frac_bits``/``payload_bits``: the
    fixed-point format, as for ``fixed``. ``source_capacity``: camera events one step may
    bring (the width of the source's port; default: the recording's busiest step).
    """

    name = "lava"
    arithmetic = "fixed"
    family = "fixed"
    fuses = False
    capabilities = frozenset({"stream"})  # no "bands": it takes no ``workers``

    def __init__(self, arithmetic: str = "fixed", frac_bits: int = DEFAULT_FRAC_BITS,
                 payload_bits: int = DEFAULT_PAYLOAD_BITS, packet_events: int = DEFAULT_PACKET_EVENTS,
                 source_capacity: int | None = None):
        super().__init__(packet_events, fuse=False)
        if arithmetic not in ("fixed", "float"):
            raise BackendError(f"lava backend: arithmetic must be 'fixed' or 'float', got {arithmetic!r}")
        if source_capacity is not None and (isinstance(source_capacity, bool) or not isinstance(source_capacity, int)
                                            or source_capacity < 1):
            raise BackendError("lava backend: source_capacity must be a positive whole number, "
                               f"got {source_capacity!r}")
        self.arithmetic = self.family = arithmetic
        self.format = FixedPointFormat(frac_bits, payload_bits) if arithmetic == "fixed" else None
        self.source_capacity = source_capacity
        require_lava()  # here, so that a run, a session or the suite stops at once with the one line

    def _format(self) -> FixedPointFormat | None:
        return self.format

    def open_stream(self, compiled, **options):
        options.pop("fuse", None)  # nothing to fuse: every process is its own Lava process
        return super().open_stream(compiled, **options)

    def _executor(self, network: Network, t0_us: int, timestep_us: int, recording: Recording,
                  probes: list[str]) -> "LavaExecutor":
        from tofnet.backends.registry import backends_by_family
        host = GraphExecutor(network, family=self.family, backend=self.name, t0_us=t0_us, timestep_us=timestep_us,
                             recording=recording, fixed_format=self._format(), probes=probes,
                             backends_by_family=backends_by_family)
        capacity = self.source_capacity or busiest_step(recording.events, t0_us, timestep_us, network)
        return LavaExecutor(host, capacity)


def busiest_step(events: np.ndarray, t0_us: int, timestep_us: int, network: Network) -> int:
    """Events of the busiest step (those before ``t0`` count in step 0); without events, 4 per pixel."""
    if not len(events):
        width, height = max((tuple(p.sensor_size) for p in network.processes), key=lambda s: s[0] * s[1])
        return 4 * width * height
    steps = np.maximum((events["t"] - t0_us) // timestep_us, 0)
    return int(np.bincount(steps - steps.min()).max())


def refuse_host_only(host: GraphExecutor) -> None:
    for node in host.nodes:
        why = type(node.model).host_only
        if why:
            raise UnsupportedError(f"process {node.process.name!r} ({type(node.process).__name__}) cannot run "
                                   f"in Lava: its {type(node.model).__name__} {why}")


def capacity_of(process, port: str, sensor_size: tuple[int, int]) -> int:
    """Records an output port may send in one step: one per pixel and channel (spikes), or a few (fields)."""
    spec = process.port(port).spec
    if spec.payload.kind == "field":
        return FIELD_RECORDS
    return spec.channels * sensor_size[0] * sensor_size[1]


class LavaExecutor:
    """The Lava processes of a network and the runtime that advances them (``GraphExecutor``'s interface).

    ``host`` is a ``GraphExecutor`` built but never run: it checked the graph and built the
    models; each Lava process takes its model over when the runtime starts (forked), and the
    host's copies stay as they were built (the state before step 0).
    """

    def __init__(self, host: GraphExecutor, source_capacity: int):
        from tofnet.backends import lava_processes as lp

        refuse_host_only(host)
        self.host, self.network = host, host.network
        self.sinks, self.probes, self.latency = host.sinks, host.probes, host.latency
        self.drain_steps, self.readers = host.drain_steps, host.readers
        self.t0_us, self.timestep_us = host.t0_us, host.timestep_us
        self.clock = 0
        self.capacity = source_capacity
        self._pending = np.empty(0, EVENT_DTYPE)  # fed, not yet given to the source
        self._latest_us: int | None = None
        self._started = False
        self._feed = lp.new_queue()
        self.failures = lp.Failures()
        source_words = lp.words_for(source_capacity, EVENT_DTYPE)
        self.source = lp.EventSource(words=source_words, feed=self._feed, t0_us=self.t0_us,
                                     timestep_us=self.timestep_us, name="event_source")
        models: dict[Any, type] = {self.source: lp.PyEventSourceModel}
        self.plans: dict[str, lp.Plan] = {}
        self.procs: dict[str, Any] = {}
        out_ports: dict[tuple[str, str], Any] = {}
        for node in host.nodes:
            plan = self._plan(node, source_words)
            proc, model_cls = lp.process_for(plan, node.model.ctx.family)
            models[proc] = model_cls
            self.plans[plan.name], self.procs[plan.name] = plan, proc
            if plan.reads_events:
                self.source.events.connect(getattr(proc, lp.CAMERA_PORT))
            for port, edges in node.inputs.items():
                for lava_name, edge in zip(plan.inputs[port], edges):
                    out_ports[(edge.source, edge.source_port)].connect(getattr(proc, lava_name))
            for port, (lava_name, _) in plan.outputs.items():
                out_ports[(plan.name, port)] = getattr(proc, lava_name)
        self.sink_queues: dict[str, Any] = {}
        for name in self.sinks + self.probes:
            proc_name, _, port = name.partition(".")
            self.sink_queues[name] = lp.new_queue()
            words = self.plans[proc_name].outputs[port][1]
            sink = lp.RecordSink(words=words, dtype=self.plans[proc_name].dtypes[port], out=self.sink_queues[name],
                                 name=f"sink {name}")
            out_ports[(proc_name, port)].connect(sink.records)
            models[sink] = lp.PyRecordSinkModel
        from lava.magma.core.run_configs import Loihi2SimCfg
        family = host.nodes[0].model.ctx.family if host.nodes else "fixed"
        self.run_cfg = Loihi2SimCfg(select_tag=lp.TAGS[family], exception_proc_model_map=models)
        self._finalizer = weakref.finalize(self, _stop, self.source)  # the runtime stops with the executor

    def _plan(self, node, source_words: int):
        """The ports, Vars and model of one process's Lava process (``lava_processes.Plan``)."""
        from tofnet.backends.lava_processes import Plan, words_for

        process = node.process
        plan = Plan(process.name, node.model, {s.name: s.payload.dtype for s in process.inports + process.outports},
                    reads_events=process.name in self.readers, source_words=source_words,
                    tally=list(node.model.counts()), failures=self.failures)
        for port, edges in node.inputs.items():
            plan.inputs[port] = [f"in_{port}" if len(edges) == 1 else f"in_{port}_{i + 1}" for i in range(len(edges))]
            for lava_name, edge in zip(plan.inputs[port], edges):
                plan.in_words[lava_name] = self.plans[edge.source].outputs[edge.source_port][1]
        for spec in process.outports:
            records = capacity_of(process, spec.name, process.sensor_size)
            plan.outputs[spec.name] = (f"out_{spec.name}", words_for(records, spec.payload.dtype))
        for var in type(process).vars:
            plan.vars[var.name] = (var.shape_for(process.sensor_size), np.dtype(var.dtype))
        return plan

    # -- events ---------------------------------------------------------------------------------
    def feed(self, events: np.ndarray) -> None:
        if len(events):
            self._pending = concat([self._pending, events], EVENT_DTYPE)
            self._latest_us = int(events["t"][-1])

    def complete_until(self) -> int | None:
        """Steps before the latest event's step have all their events (as the input filter says)."""
        if self._latest_us is None or self._latest_us < self.t0_us:
            return None
        return (self._latest_us - self.t0_us) // self.timestep_us

    # -- running --------------------------------------------------------------------------------
    def advance(self, end: int) -> dict[str, np.ndarray]:
        """Run the Lava processes over steps ``[clock, end)``; the records sinks and probes sent."""
        from lava.magma.core.run_conditions import RunSteps

        first = self.clock
        if end <= first:
            return {}
        if not self._finalizer.alive:
            raise BackendError("lava backend: Lava's runtime was stopped (after an error or close); open a new stream")
        cut = int(np.searchsorted(self._pending["t"], self.t0_us + end * self.timestep_us))
        now, self._pending = self._pending[:cut], self._pending[cut:]
        if len(now):
            steps = np.maximum((now["t"] - self.t0_us) // self.timestep_us, first)
            per_step = np.bincount(steps - first)
            if per_step.max() > self.capacity:
                raise BackendError(f"lava backend: step {first + int(per_step.argmax())} brings {int(per_step.max())} "
                                   f"events, more than the event source holds per step ({self.capacity}); "
                                   "raise the backend's source_capacity")
        self._feed.put((end, now))
        if not self._started:
            # before multiprocessing's own exit handler, which would wait for Lava's processes for ever
            atexit.register(self._finalizer)
            self._started = True
        try:
            self.source.run(condition=RunSteps(num_steps=end - first), run_cfg=self.run_cfg)
        except Exception as err:
            raise BackendError(f"lava backend: the Lava run of steps {first}..{end - 1} failed: "
                               f"{type(err).__name__}: {str(err).strip().splitlines()[-1] if str(err).strip() else ''}"
                               ) from err
        failure = self.failures.first()
        if failure is not None:
            self.release()
            raise BackendError(f"lava backend: {failure}")
        self.clock = end
        return {name: self._collect(name, q, end - 1) for name, q in self.sink_queues.items()}

    def _collect(self, name: str, q, last: int) -> np.ndarray:
        proc_name, _, port = name.partition(".")
        parts = []
        while True:
            try:
                step, records = q.get(timeout=SINK_TIMEOUT_S)
            except queue.Empty:
                raise BackendError(f"lava backend: the sink of {name} sent nothing for step {last} "
                                   f"within {SINK_TIMEOUT_S:g} s") from None
            if records is not None:
                parts.append(records)
            if step >= last:
                break
        dtype = self.plans[proc_name].dtypes[port]
        return np.concatenate(parts) if parts else np.empty(0, dtype)

    def release(self) -> None:
        """Stop the Lava runtime (its processes); the executor cannot run after this."""
        self._finalizer()
        atexit.unregister(self._finalizer)

    # -- state ----------------------------------------------------------------------------------
    def get_var(self, process: str, name: str) -> np.ndarray:
        """A variable at the start of step ``clock``: Lava's ``Var.get`` (before the first step: as built)."""
        if not self._started:
            return self.host.get_var(process, name)
        var = type(self.host.node(process).process).var(name)
        shape = self.plans[process].vars[name][0]
        return np.asarray(getattr(self.procs[process], name).get()).reshape(shape).astype(var.dtype)

    def set_var(self, process: str, name: str, value) -> None:
        """Replace a variable before step ``clock`` runs: Lava's ``Var.set`` (before the first step: the model)."""
        if not self._started:
            return self.host.set_var(process, name, value)
        var = type(self.host.node(process).process).var(name)
        if not var.settable:
            raise BackendError(f"{process}.{name} is read-only ({var.doc})")
        try:
            var.check(value, self.host.node(process).process.sensor_size)  # range and dtype, as every backend
        except ValueError as err:
            raise BackendError(f"{process}.{name}: {err}; the session is unchanged") from None
        shape = self.plans[process].vars[name][0]
        try:
            full = np.broadcast_to(np.asarray(value), shape).astype(var.dtype)
        except (ValueError, TypeError) as err:
            raise BackendError(f"{process}.{name}: expected values of shape {shape} ({var.dtype}): {err}") from None
        getattr(self.procs[process], name).set(full.astype(np.float64))

    def set_param(self, process: str, name: str, value) -> None:
        if self._started:
            raise BackendError(f"{process}.{name}: the lava backend takes parameters only before the first step "
                               "(a Lava process's parameters are fixed once its runtime starts)")
        self.host.set_param(process, name, value)

    def counts(self) -> dict[str, dict[str, int]]:
        """What each process counted: its ``tally`` Var, in the network's process order."""
        if not self._started:
            return self.host.counts()
        out = {}
        for p in self.network.processes:
            keys = self.plans[p.name].tally
            values = self.procs[p.name].tally.get()
            out[p.name] = {key: int(v) for key, v in zip(keys, values)}
        return out

    def output_latency(self, name: str) -> int:
        return self.host.output_latency(name)

    def payload_of(self, name: str) -> str:
        return self.host.payload_of(name)


def _stop(source) -> None:
    if getattr(source, "runtime", None) is not None:
        source.stop()
