"""Executing any process graph: one model per process, in topological order, one step of delay per connection.

``GraphExecutor`` advances every model over the same range of steps at a time. A
connection (``Edge``) queues the records its source sent; a model running steps
``[first, end)`` is given, on each input port, the records sent in steps before
``end - 1`` that it has not seen (those of step ``end - 1`` arrive in step ``end``), so
the result does not depend on how the steps are grouped: one range or one step at a
time give the same records (the network is feed-forward). Records move between models
in the canonical order: by step, then ``y``, then ``x`` (stable otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

import networkx as nx
import numpy as np
from numba import njit

import tofnet.numba_cache  # noqa: F401 - before any cached kernel: numba picks its cache key at decoration
from tofnet.core.network import Network
from tofnet.core.ports import InPort, OutPort
from tofnet.core.process import Process
from tofnet.errors import BackendError, NetworkError
from tofnet.kernels.order import pixel_order
from tofnet.models.base import ModelContext, apply_param, concat, take
from tofnet.models.contract import check_within, run_model, steps_text, who
from tofnet.models.registry import model_for

#: ``place(process, model_class, ctx) -> model``: builds (or places remotely) one process's model.
Placer = Callable[[Process, type, ModelContext], Any]


@njit(cache=True)
def _first_disorder(step, y, x, minor) -> int:
    """Index of the first record out of (step, y, x, minor) order, or -1."""
    for i in range(1, step.shape[0]):
        if step[i] != step[i - 1]:
            if step[i] < step[i - 1]:
                return i
            continue
        if y[i] != y[i - 1]:
            if y[i] < y[i - 1]:
                return i
            continue
        if x[i] < x[i - 1] or (x[i] == x[i - 1] and minor[i] < minor[i - 1]):
            return i
    return -1


def canonical(records: np.ndarray) -> np.ndarray:
    """``records`` in the canonical order: by step, then y, then x (then ``direction`` for
    counter spikes; stable otherwise). Returns ``records`` itself when already so; when only
    some steps are out of pixel order (packets that split a step), re-sorts just those."""
    if len(records) < 2:
        return records
    names = records.dtype.names
    step = records["step"]  # strided views of the records: numba reads them in place
    if "x" not in names or "y" not in names:
        return records if np.all(step[1:] >= step[:-1]) else records[np.argsort(step, kind="stable")]
    y, x = records["y"], records["x"]
    minor = records["direction"] if "direction" in names else np.zeros(len(records), np.uint8)
    first = _first_disorder(step, y, x, minor)
    if first < 0:
        return records
    if np.any(step[1:] < step[:-1]):
        return records[np.lexsort((minor, x, y, step))]
    order = pixel_order(step, y, x, minor, int(y.max()) + 1)
    return take(records, order)


@dataclass
class Edge:
    """One connection: records its source sent that its target has not been given yet."""

    source: str
    source_port: str
    target: str
    target_port: str
    queue: list[np.ndarray] = field(default_factory=list)

    def take(self, before: int, dtype: np.dtype) -> np.ndarray:
        """Remove and return the queued records sent before step ``before``."""
        waiting = concat(self.queue, dtype)
        cut = int(np.searchsorted(waiting["step"], before)) if len(waiting) else 0
        self.queue = [waiting[cut:]] if cut < len(waiting) else []
        return waiting[:cut]


@dataclass
class Node:
    """A process, its model (or a stand-in for one running elsewhere) and its connections."""

    process: Process
    model: Any
    inputs: dict[str, list[Edge]]
    outputs: dict[str, list[Edge]]
    #: How errors name it: ``process 'f' (FaultyModel)``, the model's class even when a stand-in runs it.
    name: str = ""


def resolve_probes(network: Network, probes: Iterable[str], record_tot: bool = False) -> list[str]:
    """Probe names checked against the network (``process.port`` of an output port)."""
    names = list(dict.fromkeys(probes))
    if record_tot:
        names += [port.qualified_name for p in network.processes for port in p.ports.values()
                  if isinstance(port, OutPort) and port.spec.payload.name == "count" and port.qualified_name not in names]
    for name in names:
        proc_name, _, port_name = str(name).partition(".")
        port = network.process(proc_name).port(port_name)
        if isinstance(port, InPort):
            sources = ", ".join(s.qualified_name for s in port.sources) or "nothing"
            raise NetworkError(f"probe {name}: an input port; probe the output feeding it ({sources})")
    return names


def sinks_of(network: Network) -> list[str]:
    """Output ports connected to nothing: what a run returns."""
    return [port.qualified_name for p in network.processes for port in p.ports.values()
            if isinstance(port, OutPort) and not port.targets]


def latencies(network: Network, readers: set[str], added: dict[str, dict[str, int]] | None = None) -> dict[str, int]:
    """Per output port (``process.port``): steps from an event to what it sends, on the longest path
    from an event-reading process: one per connection, plus the steps the process adds before
    that port (``added[process][port]``, ``Model.latency_steps``; 0 if not given)."""
    added = added or {}
    out: dict[str, int] = {}
    for name in nx.topological_sort(network.graph):
        process = network.process(name)
        ports = [p for p in process.ports.values() if isinstance(p, OutPort)]
        arrivals = [out[source.qualified_name] + 1 for port in process.ports.values() if isinstance(port, InPort)
                    for source in port.sources if out[source.qualified_name] >= 0]
        ready = max(arrivals, default=0 if name in readers else -1)  # -1: nothing from the events reaches it
        for port in ports:
            out[port.qualified_name] = ready + added.get(name, {}).get(port.name, 0) if ready >= 0 else -1
    return {name: max(d, 0) for name, d in out.items()}


class GraphExecutor:
    """Runs a network's models over ranges of steps; returns what sinks and probes sent.

    ``family`` picks the models (``tofnet.models.registry``); ``place`` may build a
    model elsewhere (``multiproc``). ``recording`` is the camera's metadata (its events are
    not read here: ``feed`` gives them). ``t0_us``/``timestep_us``: the clock.
    """

    def __init__(self, network: Network, *, family: str, backend: str, t0_us: int, timestep_us: int,
                 recording=None, fixed_format=None, probes: Iterable[str] = (),
                 backends_by_family: Callable[[], dict[str, list[str]]] | None = None, place: Placer | None = None):
        self.network = network
        self.t0_us, self.timestep_us = t0_us, timestep_us
        self.clock = 0
        self.sinks = sinks_of(network)
        self.probes = [p for p in probes if p not in self.sinks]
        self.wanted = set(self.sinks) | set(self.probes)
        order = network.topological_order()
        classes = {p.name: model_for(p, family, backend, backends_by_family) for p in order}
        self.readers = {name for name, cls in classes.items() if cls.reads_events}
        self.latency = latencies(network, self.readers,
                                 {p.name: classes[p.name].latency_steps(p) for p in order})
        self.edges = [Edge(src.process.name, src.name, dst.process.name, dst.name)
                      for src, dst in network.connections()]
        metas: dict[str, dict[str, Any]] = {}
        self.nodes: list[Node] = []
        for process in order:
            inputs = {s.name: [e for e in self.edges if e.target == process.name and e.target_port == s.name]
                      for s in process.inports}
            outputs = {s.name: [e for e in self.edges if e.source == process.name and e.source_port == s.name]
                       for s in process.outports}
            ctx = ModelContext(family, tuple(process.sensor_size), t0_us, timestep_us, fixed_format, recording,
                               None, {port: [metas[e.source].get(e.source_port) for e in edges]
                                      for port, edges in inputs.items()})
            cls = classes[process.name]
            metas[process.name] = cls.output_meta(process, ctx)
            model = place(process, cls, ctx) if place is not None else cls(process, ctx)
            self.nodes.append(Node(process, model, inputs, outputs, who(process, cls)))
        self.drain_steps = max(self.latency.values(), default=0)

    # -- events -------------------------------------------------------------------------------
    def feed(self, events: np.ndarray) -> None:
        """Give camera events (time order) to every event-reading model."""
        for node in self.nodes:
            if node.process.name in self.readers:
                node.model.feed(events)

    def complete_until(self) -> int | None:
        """Steps before this one have all their events (None: no event has come yet)."""
        marks = [node.model.complete_until() for node in self.nodes if node.process.name in self.readers]
        if not marks or any(m is None for m in marks):
            return None
        return min(marks)

    # -- running ------------------------------------------------------------------------------
    def advance(self, end: int) -> dict[str, np.ndarray]:
        """Run every model over steps ``[clock, end)``; the records sinks and probes sent."""
        first = self.clock
        if end <= first:
            return {}
        collected: dict[str, np.ndarray] = {}
        for node in self.nodes:
            process = node.process
            inputs = {}
            for port, edges in node.inputs.items():
                dtype = process.port(port).spec.payload.dtype
                parts = [edge.take(end - 1, dtype) for edge in edges]
                inputs[port] = parts[0] if len(parts) == 1 else canonical(concat(parts, dtype))
            # checked here, for every backend alike: a spike outside the size would wrap into the next row of a
            # kernel's state, or be routed to no core, or index past a dense array
            sent = run_model(process, node.model, first, end, inputs, node.name)
            for port, edges in node.outputs.items():
                records = sent.get(port)
                if records is None:
                    continue
                check_within(node.name, process, port, records, steps_text(first, end))
                records = canonical(records)
                for edge in edges:
                    if len(records):
                        edge.queue.append(records)
                name = f"{process.name}.{port}"
                if name in self.wanted:
                    collected[name] = records
        self.clock = end
        return collected

    # -- state between runs (sessions) ---------------------------------------------------------
    def node(self, name: str) -> Node:
        for node in self.nodes:
            if node.process.name == name:
                return node
        self.network.process(name)  # raises naming the processes
        raise NetworkError(f"no process {name!r}")

    def get_var(self, process: str, name: str) -> np.ndarray:
        """Variable ``name`` of ``process`` at the start of step ``clock`` (every earlier step ran)."""
        node = self.node(process)
        var = type(node.process).var(name)
        value = np.asarray(node.model.get_var(name, self.clock))
        expected = var.shape_for(node.process.sensor_size)
        if value.shape != expected:
            raise BackendError(f"{process}.{name}: the model returned shape {value.shape}, expected {expected}")
        return value.astype(var.dtype, copy=False)

    def set_var(self, process: str, name: str, value) -> None:
        """Replace a settable variable before step ``clock`` runs (any array broadcastable to its shape)."""
        node = self.node(process)
        var = type(node.process).var(name)
        if not var.settable:
            raise BackendError(f"{process}.{name} is read-only ({var.doc})")
        try:
            full = var.check(value, node.process.sensor_size)
        except ValueError as err:
            raise BackendError(f"{process}.{name}: {err}; the session is unchanged") from None
        node.model.set_var(name, full, self.clock)

    def set_param(self, process: str, name: str, value) -> None:
        """Change a parameter from step ``clock`` on, with the declaration's checks; the model must accept it."""
        node = self.node(process)
        apply_param([(node.process, node.model)], name, value)  # converts and checks, or raises naming the field

    def counts(self) -> dict[str, dict[str, int]]:
        """What each process counted, in the network's process order."""
        by_name = {node.process.name: dict(node.model.counts()) for node in self.nodes}
        return {p.name: by_name[p.name] for p in self.network.processes}

    def output_latency(self, name: str) -> int:
        return self.latency[name]

    def payload_of(self, name: str) -> str:
        proc_name, _, port = name.partition(".")
        return self.network.process(proc_name).port(port).spec.payload.name
