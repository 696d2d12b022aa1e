"""What every backend takes and returns."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from tofnet.compiler.compiled import network_of
from tofnet.core.counters import kinds_of
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE
from tofnet.units import seconds_of

#: Summary keys that depend on how and where a run went, not on what it computed.
RUN_SPECIFIC = ("backend", "wall_time_s", "setup_time_s", "read_time_s", "compile_time_s", "kernels_compiled",
                "workers")
#: Summary keys for reports only, not stored with the depth files' facts (those stay as they were).
REPORT_ONLY = ("readers", "latency")

#: ``progress(done, total)``: called now and then with events processed so far.
ProgressCallback = Callable[[int, int], None]


def payloads_of(network, names: Iterable[str]) -> dict[str, str]:
    """The payload each output port (``process.port``) of ``network`` sends, by name."""
    out = {}
    for name in names:
        proc, _, port = name.partition(".")
        out[name] = network.process(proc).port(port).spec.payload.name
    return out


def declared_of(network) -> dict[str, dict[str, dict]]:
    """What each process of ``network`` declares it counts (``Process.counters``, as plain data)."""
    return {p.name: kinds_of(type(p).counters) for p in network.processes}


@dataclass
class RunResult:
    """The output of every sink (and probed) port and the counts that account for every event.

    ``outputs["process.port"]`` holds the records the port sent, in the canonical order
    (step, then y, then x); ``payloads`` names each one's payload. ``counts[process]`` is
    what each process counted (input: ``events_in``, ``accepted`` and a count per drop
    reason; time of travel: ``spikes``; depth: each reject reason and ``emitted``).
    ``latency[output]`` is the steps from an input event to that output (one per connection
    on the longest path, plus what each process declares it adds before the output port on
    the way: ``Process.port_latency_steps``). For the paper's network the properties below read as before:
    ``depth``, ``events_in == accepted + sum(dropped.values())``, ``rejected``, ``tot``.
    """

    backend: str
    outputs: dict[str, np.ndarray]
    counts: dict[str, dict[str, int]]
    steps: int
    t0_us: int
    timestep_us: int
    latency: dict[str, int]
    # None only to be refused in one line below (a required field left out was a TypeError's traceback)
    payloads: dict[str, str] | None = None
    declared: dict[str, dict[str, dict]] | None = None
    wall_time: float = 0.0
    extra: dict = field(default_factory=dict)
    #: Seconds the run spent compiling kernels or loading numba's cache (not in ``wall_time``), and
    #: the kernels it compiled (0 once numba's cache holds them: first run only).
    compile_time: float = 0.0
    kernels_compiled: int = 0
    #: Seconds the run spent setting up and tearing down (building the kernels' state, starting and
    #: stopping worker processes; not in ``wall_time``).
    setup_time: float = 0.0
    #: Seconds spent reading the input between packets (a file streamed in chunks; not in ``wall_time``).
    read_time: float = 0.0

    def __post_init__(self) -> None:
        unnamed = [name for name in self.outputs if name not in (self.payloads or {})]
        undeclared = [name for name in self.counts if name not in (self.declared or {})]
        if unnamed or undeclared or self.payloads is None or self.declared is None:
            raise BackendError(f"RunResult of backend {self.backend!r}: expected payloads naming every output and "
                               f"declared counts of every counted process (RunResult.of(network, ...) derives "
                               f"both); no payload for {unnamed}, no declared counts for {undeclared}")

    @classmethod
    def of(cls, network, backend: str, outputs: dict[str, np.ndarray], counts: dict[str, dict[str, int]], *,
           steps: int, t0_us: int, timestep_us: int, latency: dict[str, int], **rest) -> "RunResult":
        """The result of running ``network`` (a ``Network`` or ``CompiledNetwork``), its ``payloads`` and
        ``declared`` derived from it: the one way every backend builds its result. ``latency`` names
        every output the run returns (a stream's ``outputs`` may hold fewer until its run joins them);
        ``rest``: ``extra`` and the times."""
        network = network_of(network)
        return cls(backend, outputs, counts, steps, t0_us, timestep_us, latency, payloads_of(network, latency),
                   declared_of(network), **rest)

    def timed_by(self, clock) -> "RunResult":
        """Take the times of a ``tofnet.kernels.compilation.Stopwatch`` started with the run."""
        self.wall_time, self.compile_time, self.kernels_compiled = (clock.network_seconds(), clock.compile_seconds,
                                                                    clock.compiled)
        self.setup_time, self.read_time = clock.setup_seconds, clock.reading_seconds
        return self

    # -- the paper network's view -------------------------------------------------------------
    def _named(self, payload: str) -> list[str]:
        return [name for name, kind in self.payloads.items() if kind == payload]

    @property
    def depth_outputs(self) -> list[str]:
        """Names of the outputs that carry depth estimates (``DEPTH_DTYPE``)."""
        return self._named("depth")

    @property
    def depth_output(self) -> str:
        names = self.depth_outputs
        if len(names) != 1:
            what = ", ".join(names) if names else "none"
            raise BackendError(f"the network has {len(names)} depth outputs ({what}); "
                               "read result.outputs[name] instead of result.depth")
        return names[0]

    @property
    def depth(self) -> np.ndarray:
        """The estimates of the network's one depth output (``DEPTH_DTYPE``)."""
        if not self.depth_outputs:
            return np.empty(0, DEPTH_DTYPE)
        return self.outputs[self.depth_output]

    @depth.setter
    def depth(self, value: np.ndarray) -> None:
        self.outputs[self.depth_output] = value

    def of_kind(self, process: str, kind: str) -> dict[str, int]:
        """The counts of ``process`` whose declared kind is ``kind`` (``tofnet.core.counters.KINDS``)."""
        counted = self.counts.get(process, {})
        return {name: int(counted.get(name, 0)) for name, what in self.declared.get(process, {}).items()
                if what["kind"] == kind}

    @property
    def readers(self) -> dict[str, dict]:
        """Per process that reads the events: ``events_in``, ``accepted`` and ``dropped`` by reason
        (each accounts for every event once)."""
        return {name: {"events_in": sum(self.of_kind(name, "read").values()),
                       "accepted": sum(self.of_kind(name, "accepted").values()),
                       "dropped": self.of_kind(name, "dropped")}
                for name in self.counts if self.of_kind(name, "read")}

    def _first_reader(self) -> dict:
        return next(iter(self.readers.values()), {"events_in": 0, "accepted": 0, "dropped": {}})

    @property
    def events_in(self) -> int:
        """Events the network was given (each reader reads every event)."""
        return self._first_reader()["events_in"]

    @property
    def accepted(self) -> int:
        """Events the first reader accepted (``readers`` has every reader's)."""
        return self._first_reader()["accepted"]

    @property
    def dropped(self) -> dict[str, int]:
        """The first reader's drops by reason (``readers`` has every reader's)."""
        return self._first_reader()["dropped"]

    @property
    def rejected(self) -> dict[str, int]:
        """Rejections by reason of the process behind the depth output."""
        if len(self.depth_outputs) != 1:
            return {}
        return self.of_kind(self.depth_output.split(".")[0], "rejected")

    def totals(self) -> dict[str, int]:
        """The summary's totals (``Count.total``, e.g. ``tot_spikes``), summed over the processes."""
        out: dict[str, int] = {}
        for process, declared in self.declared.items():
            for name, what in declared.items():
                if what.get("total"):
                    out[what["total"]] = out.get(what["total"], 0) + int(self.counts.get(process, {}).get(name, 0))
        return out

    @property
    def tot_spikes(self) -> int:
        """Time-of-travel spikes sent (the ``tot_spikes`` total)."""
        return self.totals().get("tot_spikes", 0)

    @property
    def tot(self) -> np.ndarray | None:
        """The probed time-of-travel spikes (``TOT_DTYPE``), when exactly one counts port was probed."""
        names = self._named("count")
        return self.outputs[names[0]] if len(names) == 1 else None

    @property
    def latency_steps(self) -> int:
        """Steps from an event to the depth output (the longest of several; of any output without one)."""
        names = self.depth_outputs or list(self.latency)
        return max((self.latency[n] for n in names), default=0)

    @property
    def latency_seconds(self) -> float:
        """Seconds from an event to the depth output (``latency_steps`` steps of ``timestep_us``)."""
        return seconds_of(self.latency_steps * self.timestep_us)

    def facts(self) -> dict:
        """What the run computed, the same on every backend of one arithmetic: counts, outputs, steps,
        latency (no backend name, times or machine facts). Depth files store this, so that integer
        backends write the same bytes."""
        return {k: v for k, v in self.summary().items() if k not in RUN_SPECIFIC + REPORT_ONLY}

    def summary(self) -> dict:
        """Plain-data summary (for JSON and the CLI)."""
        out = {"backend": self.backend, "events_in": self.events_in, "accepted": self.accepted,
               "dropped": self.dropped, "tot_spikes": 0, **self.totals()}
        if len(self.depth_outputs) == 1:
            out["depth_out"] = int(len(self.depth))
            out["rejected"] = self.rejected
        out.update({
            "outputs": {name: int(len(records)) for name, records in self.outputs.items()},
            "counts": {name: dict(c) for name, c in self.counts.items()},
            "readers": self.readers, "latency": dict(self.latency),
            "steps": self.steps, "timestep_s": seconds_of(self.timestep_us), "latency_steps": self.latency_steps,
            "latency_s": self.latency_seconds, "wall_time_s": self.wall_time,
            "setup_time_s": self.setup_time, "read_time_s": self.read_time, "compile_time_s": self.compile_time, "kernels_compiled": self.kernels_compiled})
        if "bands" in self.extra:  # how the work was split (workers, bands of rows, what ran whole)
            out["workers"] = {"threads": int(self.extra.get("workers", 1)), "bands": len(self.extra["bands"]),
                              "whole": list(self.extra.get("whole", [])),
                              "unit": str(self.extra.get("unit", "threads"))}  # "threads" counts processes then
            if "one_band" in self.extra:  # why a run that asked for workers kept one band
                out["workers"]["one_band"] = str(self.extra["one_band"])
        return out


class Backend(ABC):
    """Executes a compiled network on a recording.

    ``arithmetic`` is ``"float"`` or ``"fixed"``; integer backends must agree bit for
    bit, float ones within the tolerance stated in docs/fixed_point.md. ``family`` names
    the process models it runs (``tofnet.models.registry``).
    """

    name: str = ""
    arithmetic: str = "float"
    family: str = "float"
    #: What a ``Session`` may ask of it (declared, never probed): ``"stream"``: ``open_stream(compiled,
    #: fuse=..., recording=..., ...)`` as ``LocalBackend``'s; ``"workers"``: ``session(compiled)`` keeps
    #: worker processes for a session's lifetime; ``"open session"``: it is such a running session;
    #: ``"bands"``: it takes ``workers=N`` (the sensor cut into N bands of rows, the same bytes for every
    #: N: ``tofnet conformance --workers`` checks it, and is n/a without it).
    capabilities: frozenset[str] = frozenset()
    #: The ways it offers to run one network (a name, the options that select it), each of which
    #: must give the same bytes with any number of ``workers`` (``tofnet.conformance.workers``).
    run_modes: tuple[tuple[str, dict], ...] = (("default", {}),)

    @abstractmethod
    def run(self, compiled, recording, *, probes: Iterable[str] = (), record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        """Run ``compiled`` (a ``CompiledNetwork`` or ``Network``) on ``recording`` (a ``Recording``).

        ``probes`` names output ports (``"process.port"``) to record besides the sinks;
        ``record_tot`` probes every time-of-travel counter port.
        """
