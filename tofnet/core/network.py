"""A network: processes and their connections, held as a networkx graph."""

from __future__ import annotations

from typing import Iterable, Iterator

import networkx as nx

from tofnet.core.ports import InPort, OutPort
from tofnet.core.process import Process
from tofnet.errors import NetworkError


class Network:
    """Processes connected port to port; validated on construction.

    Nodes of ``graph`` are process names (attribute ``process``); each edge carries
    ``source_port`` and ``target_port`` names. Every connection delivers the spikes
    sent in step k at step k+1.
    """

    def __init__(self, processes: Iterable[Process], name: str = "network"):
        self.name = name
        self.graph = nx.MultiDiGraph()
        for process in processes:
            if not isinstance(process, Process):
                raise NetworkError(f"network {name!r}: expected processes, got {process!r}")
            if process.name in self.graph:
                other = self.graph.nodes[process.name]["process"]
                raise NetworkError(f"network {name!r}: two processes are named {process.name!r} "
                                   f"({type(other).__name__} and {type(process).__name__}); give each a unique name=")
            self.graph.add_node(process.name, process=process)
        for process in self.processes:
            for port in process.ports.values():
                if isinstance(port, OutPort):
                    for target in port.targets:
                        if target.process.name not in self.graph or self.process(target.process.name) is not target.process:
                            raise NetworkError(f"{port.qualified_name} is connected to {target.qualified_name}, "
                                               "whose process is not in the network")
                        self.graph.add_edge(process.name, target.process.name,
                                            source_port=port.name, target_port=target.name)
                else:
                    for source in port.sources:
                        if source.process.name not in self.graph:
                            raise NetworkError(f"{port.qualified_name} is connected from {source.qualified_name}, "
                                               "whose process is not in the network")
        self.validate()

    @property
    def processes(self) -> list[Process]:
        """Processes in insertion order."""
        return [data["process"] for _, data in self.graph.nodes(data=True)]

    def process(self, name: str) -> Process:
        try:
            return self.graph.nodes[name]["process"]
        except KeyError:
            raise NetworkError(f"network {self.name!r} has no process {name!r}; "
                               f"processes: {', '.join(self.graph.nodes)}") from None

    def of_type(self, cls: type[Process]) -> list[Process]:
        """The processes that are instances of ``cls``."""
        return [p for p in self.processes if isinstance(p, cls)]

    def connections(self) -> Iterator[tuple[OutPort, InPort]]:
        """Every (source port, target port) pair."""
        for src, dst, data in self.graph.edges(data=True):
            yield (self.process(src).port(data["source_port"]), self.process(dst).port(data["target_port"]))

    def topological_order(self) -> list[Process]:
        return [self.process(n) for n in nx.topological_sort(self.graph)]

    def validate(self) -> None:
        """Raise ``NetworkError`` naming the first problem: cycle, unconnected input, shape mismatch."""
        if not nx.is_directed_acyclic_graph(self.graph):
            cycle = nx.find_cycle(self.graph)
            path = " -> ".join([edge[0] for edge in cycle] + [cycle[0][0]])
            raise NetworkError(f"network {self.name!r} has a cycle ({path}); tofnet networks are feed-forward")
        for process in self.processes:
            for port in process.ports.values():
                if isinstance(port, InPort) and port.spec.required and port.source is None:
                    raise NetworkError(f"input {port.qualified_name} is not connected "
                                       f"(it expects {port.spec.payload.value} spikes: {port.spec.doc})")
        self._propagate_sensor_size()

    def _propagate_sensor_size(self) -> None:
        # Sizes flow downstream so that only the input process needs one; an explicit
        # size that disagrees with its source is a shape mismatch.
        for process in self.topological_order():
            for port in process.ports.values():
                if not isinstance(port, InPort):
                    continue
                for source in port.sources:
                    upstream = source.process.sensor_size
                    if upstream is None:
                        continue
                    if process.sensor_size is None:
                        process.sensor_size = upstream
                    elif process.sensor_size != upstream:
                        w, h = upstream
                        raise NetworkError(f"shape mismatch: {port.qualified_name} is {process.sensor_size[0]}x"
                                           f"{process.sensor_size[1]} px but its source {source.qualified_name} "
                                           f"is {w}x{h} px")
        for process in self.processes:
            # A source without a size (e.g. the velocity process) takes its target's.
            if process.sensor_size is None:
                sizes = {t.process.sensor_size for port in process.ports.values()
                         if isinstance(port, OutPort) for t in port.targets} - {None}
                if len(sizes) == 1:
                    process.sensor_size = sizes.pop()
            if process.sensor_size is None:
                raise NetworkError(f"{process.name}: sensor_size is unknown; set it on the process "
                                   "or connect it to one that has it")

    @property
    def sensor_size(self) -> tuple[int, int]:
        """(width, height) in pixels, shared by every process after validation."""
        return self.processes[0].sensor_size

    def __repr__(self) -> str:
        return f"Network({self.name!r}, processes={[p.name for p in self.processes]})"
