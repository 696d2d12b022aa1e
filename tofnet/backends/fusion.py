"""Fusion: the paper's chain recognised in a graph and run by one kernel (an optimisation only).

When a network is exactly input -> time of travel -> depth <- velocity (whatever the
process names), the event-driven backends run it with the fused kernel of
``tofnet.kernels.time_of_travel``: one pass over the events for the input filter, the
units and the depth neurons, estimates written as events arrive. It computes what the
per-process models compute, bit for bit (tests/test_fusion.py); any other graph, or a
probe inside the chain, runs the models one by one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.backends.base import RunResult
from tofnet.backends.graph import canonical, latencies
from tofnet.backends.runtime import clock_of
from tofnet.backends.stream import check_packet
from tofnet.core.network import Network
from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, TOT_DTYPE
from tofnet.io.recording import Recording, VelocitySource
from tofnet.kernels.compilation import Stopwatch
from tofnet.kernels.fixed_point import FixedPointFormat
from tofnet.kernels.kernel_config import InputFilterSettings, UnitSettings
from tofnet.kernels.region import KernelConfig, KernelOutput, TimeOfTravelKernel, copy_records
from tofnet.models.base import Model, concat
from tofnet.models.binding import UpdateRows, velocity_table
from tofnet.models.depth import OUTCOMES, depth_settings
from tofnet.models.input import check_time_order, filter_settings, input_counts
from tofnet.models.time_of_travel import unit_settings
from tofnet.models.velocity import velocity_field, velocity_source
from tofnet.models.registry import _registered
from tofnet.processes import DepthProcess, InputProcess, TimeOfTravelProcess, VelocityProcess

#: Velocity updates computed ahead of the stream, so that a packet rarely pays for them.
VELOCITY_LOOKAHEAD = 1024


@dataclass(frozen=True)
class PipelineParams:
    """The paper's chain recognised: its processes (input, time of travel, depth, velocity) and the
    settings of its kernels made by the models' own conversions (``*_settings``), on the network's
    clock (``timestep_us``, µs)."""

    sensor_size: tuple[int, int]
    timestep_us: int
    input_filter: InputFilterSettings
    units: UnitSettings
    depth: DepthProcess
    velocity: VelocityProcess
    names: tuple[str, str, str, str]  # input, time-of-travel, depth, velocity
    network: Network  # the four processes (a result's payloads and declared counts come from it)
    #: Per output port: steps from an input event to it (``graph.latencies``, from the declarations).
    latency: dict[str, int]

    @property
    def latency_steps(self) -> int:
        """Steps from an input event to its depth (2: one per connection, input -> ToT -> depth)."""
        return self.latency[f"{self.names[2]}.depth"]

    def kernel_config(self, recording: Recording | None, fixed: FixedPointFormat | None) -> KernelConfig:
        """The fused kernel's configuration, the camera from ``recording`` (its metadata) where the
        velocity process takes it; ``fixed`` the fixed-point format (None: float64)."""
        field = velocity_field(self.velocity, self.sensor_size, recording)
        return KernelConfig(sensor_size=tuple(self.sensor_size), timestep_us=self.timestep_us, units=self.units,
                            depth=depth_settings(self.depth, field, int(self.velocity.update_every)),
                            input_filter=self.input_filter, fixed=fixed)

    def velocity_source(self, recording: Recording | None) -> VelocitySource:
        """The camera velocity the velocity process reads (``recording``: its metadata)."""
        return velocity_source(self.velocity, recording)


_CHAIN = (InputProcess, TimeOfTravelProcess, DepthProcess, VelocityProcess)


def paper_chain(network: Network, family: str, probes=()) -> PipelineParams | None:
    """The chain when ``network`` is exactly the paper's four processes, else None.

    The processes must be of exactly those types with tofnet's own models for ``family``
    (a subclass or a user-registered model runs unfused), connected input.events ->
    tot.events, tot.counts -> depth.counts, velocity.a_t -> depth.a_t and nothing else;
    probes may name only the counters and the depth.
    """
    procs = network.processes
    if len(procs) != 4 or sorted(type(p).__name__ for p in procs) != sorted(c.__name__ for c in _CHAIN):
        return None
    by_type = {type(p): p for p in procs}
    if set(by_type) != set(_CHAIN) or any((cls, family) in _registered for cls in _CHAIN):
        return None
    inp, tot, dep, vel = (by_type[c] for c in _CHAIN)
    expected = {(inp.events, tot.events), (tot.counts, dep.counts), (vel.a_t, dep.a_t)}
    if set(network.connections()) != expected or len(list(network.connections())) != 3:
        return None
    if not set(probes) <= {tot.counts.qualified_name, dep.depth.qualified_name}:
        return None
    return PipelineParams(sensor_size=network.sensor_size, timestep_us=clock_of(network).timestep_us,
                          input_filter=filter_settings(inp), units=unit_settings(tot), depth=dep, velocity=vel,
                          names=(inp.name, tot.name, dep.name, vel.name), network=network,
                          latency=latencies(network, {inp.name}, {p.name: Model.latency_steps(p) for p in procs}))


def pipeline_of(network: Network) -> PipelineParams:
    """``paper_chain`` for the fixed family, raising when the network is not the paper's chain."""
    found = paper_chain(network, "fixed")
    if found is None:
        raise BackendError(f"network {network.name!r} is not input -> time_of_travel -> depth <- velocity")
    return found


class FusedStream:
    """The paper's chain on a live event stream through the fused kernel (the ``GraphStream`` API).

    ``feed`` returns estimates as soon as the event that triggers them is fed (a partial
    step's too, in the kernel's order); ``feed_all`` keeps the GraphStream contract and
    returns what it would: the records of the steps the packet completed (a later event or
    ``until_us`` completes a step), in canonical order. Memory is fixed by the sensor and the
    largest packet.
    """

    def __init__(self, backend: str, config: KernelConfig, pipeline: PipelineParams,
                 velocity_source: VelocitySource, t0_us: int | None, record_tot: bool = False,
                 order: list[str] | None = None, kernel=None):
        self.backend = backend
        self.pipeline = pipeline
        #: The stream's time: running, compiling kernels, and set-up (building the kernel's state, its bands).
        self.clock = Stopwatch()
        # ``kernel``: another implementation of the kernel's streaming API (bands: ``BandedKernel``)
        with self.clock.aside():  # the state's first touch: ~0.1 s at 1280x720
            self.kernel = kernel if kernel is not None else TimeOfTravelKernel(config, t0_us=t0_us or 0)
        self.velocity_source = velocity_source
        self.t0_us = t0_us
        self.timestep_us = pipeline.timestep_us
        self.record_tot = record_tot
        self.order = list(order or pipeline.names)
        names = pipeline.names
        self.depth_name, self.tot_name = f"{names[2]}.depth", f"{names[1]}.counts"
        self.sinks = [self.depth_name]
        self.payloads = {self.depth_name: "depth", **({self.tot_name: "count"} if record_tot else {})}
        self.primary = self.depth_name
        #: Time-of-travel spikes of the latest ``feed`` (``TOT_DTYPE``) when ``record_tot``.
        self.tot: np.ndarray | None = None
        self._events_in = 0
        self._last_event_us: int | None = None
        self._latest_us: int | None = None  # the last event's time or a promise (``until_us``), the later
        self._prepared = False  # the kernel's ``prepare`` ran (its bands are built)
        self._held: dict[str, np.ndarray] = {}  # feed_all: records of steps not complete yet
        # velocity updates (``VelocityRows``: ``self._updates.rows``), computed ``VELOCITY_LOOKAHEAD`` ahead
        self._updates = UpdateRows(lambda first, count: velocity_table(
            self.velocity_source, self.kernel.t0_us, config.timestep_us, config.update_every, count, first),
            VELOCITY_LOOKAHEAD)
        self._closed = False
        #: Called once when the stream closes or is given up (e.g. to stop its backend's workers).
        self.releases: list = []

    def check(self, events: np.ndarray, until_us: int | None = None) -> None:
        """Refuse (changing nothing) a packet ``feed_all`` would refuse, as ``GraphStream.check``: a closed
        stream, not an event array, times out of range, out of order or before an earlier packet's or promise."""
        self._admit(events, until_us)
        if len(events):
            check_time_order(events, self._latest_us, "stream")

    def _promised(self, until_us: int) -> None:
        self._latest_us = until_us if self._latest_us is None else max(self._latest_us, until_us)

    def _admit(self, events: np.ndarray, until_us: int | None = None) -> tuple[int, int] | None:
        """Checks before anything changes (the kernel checks the time order itself), ``until_us`` as the
        graph stream's; the packet's first and last times (µs), None when it is empty."""
        if self._closed:
            raise BackendError("stream is closed")
        return check_packet(events, until_us)

    def _kernel_call(self, events: np.ndarray, span: tuple[int, int], until_us: int | None, into: np.ndarray,
                     offset: int, output: bool, canonical: bool = True):
        """The kernel on a non-empty packet (first and last times ``span``, µs), writing ``into[offset:]``:
        ``run_events``' result (estimates in canonical order or, without ``canonical``, in their
        trigger events' order), or with ``output`` its ``KernelOutput``. The stream's own state
        changes only once it succeeded."""
        first = self.t0_us is None
        kernel = self.kernel
        if not self._prepared:  # bands built for the first packet's size (once: a context per 1 ms packet costs ~1 µs)
            self.expect_packets(len(events))
        if first:
            kernel.t0_us = span[0]
        try:
            if output:
                result = kernel.process_events(events, self._updates.rows, record_tot=self.record_tot, into=into,
                                               offset=offset, copy=False)
            else:
                result = kernel.run_events(events, self._updates.rows, into, offset, self.record_tot, span,
                                            canonical)
        except BaseException:
            if first:
                kernel.t0_us = 0
            raise
        if first:
            self.t0_us = kernel.t0_us
        self._last_event_us = span[1]
        self._promised(span[1])
        self._events_in += len(events)
        if until_us is not None:
            kernel.promise(until_us)
            self._promised(until_us)
        return result

    def feed(self, events: np.ndarray, until_us: int | None = None) -> np.ndarray:
        """Depth estimates (``DEPTH_DTYPE``) produced by ``events`` (``EVENT_DTYPE``, time-ordered),
        in the order of the events that triggered them."""
        return self._feed(events, until_us, False)

    def _feed(self, events: np.ndarray, until_us: int | None, canonical: bool) -> np.ndarray:
        span = self._admit(events, until_us)
        until_us = None if until_us is None else int(until_us)
        into = np.empty(len(events), DEPTH_DTYPE)  # the kernel writes the caller's array: no copy
        if span is None:
            if until_us is not None:
                self.kernel.promise(until_us)
                self._promised(until_us)
            self.tot = np.empty(0, TOT_DTYPE) if self.record_tot else None
            return into
        end, n_tot = self._kernel_call(events, span, until_us, into, 0, False, canonical)
        self.tot = copy_records(self.kernel.buffers()[2][:n_tot]) if self.record_tot else None
        return into[:end]

    def expect_packets(self, n_events: int) -> None:
        """A run feeds packets of about ``n_events`` (its chunks; progress may cut them into smaller pieces): the
        kernel's bands are chosen and built for that size now, not for the first piece."""
        prepare = getattr(self.kernel, "prepare", None)  # set-up, not running
        if prepare is not None and not self._prepared:
            with self.clock.aside():
                prepare(n_events)
        self._prepared = True

    def expect_whole_run(self) -> None:
        """A run over a whole recording, not a live stream: its bands (workers) from the first packet, whatever
        its size (a stream otherwise keeps one band on a small first packet, where bands cost latency)."""
        if hasattr(self.kernel, "one_band_below"):
            self.kernel.one_band_below = 0

    def feed_all(self, events: np.ndarray, until_us: int | None = None) -> dict[str, np.ndarray]:
        """The records of the steps this packet completed, canonical order (as ``GraphStream``)."""
        depth = self._feed(events, until_us, True)
        # kept beyond the packet: a view would hold the whole packet-sized buffer
        new = {self.depth_name: copy_records(depth) if 2 * len(depth) < len(events) else depth}
        if self.record_tot:
            new[self.tot_name] = self.tot
        horizon = None  # records of steps from here on wait (a later event or until_us completes them)
        if self._last_event_us is not None:
            horizon = (self._last_event_us - self.t0_us) // self.timestep_us
            if until_us is not None:
                horizon = max(horizon, (until_us - self.t0_us) // self.timestep_us)
        out = {}
        for name, records in new.items():
            held = self._held.pop(name, None)
            if held is not None and len(held):
                records = concat([held, records], None)
            # the kernel writes records in event order, so their steps never decrease
            cut = len(records) if horizon is None else int(np.searchsorted(records["step"], horizon, "left"))
            if cut < len(records):
                self._held[name] = copy_records(records[cut:])
            out[name] = canonical(records[:cut])
        return out

    def feed_into(self, events: np.ndarray, into: np.ndarray, offset: int) -> KernelOutput | None:
        """Like ``feed``, but write the estimates to ``into[offset:]`` (room for ``len(events)``).

        Returns the kernel's output (``depth`` a view of ``into``; ``tot`` valid until the next
        call, no ``z_raw``), None for an empty packet. Spares a copy when the caller collects the estimates.
        """
        span = self._admit(events)
        return self._kernel_call(events, span, None, into, offset, True) if span is not None else None

    def _empty(self, name: str) -> np.ndarray:
        return np.empty(0, DEPTH_DTYPE if name == self.depth_name else TOT_DTYPE)

    def abort(self) -> None:
        """Give up the stream (after its caller failed)."""
        self._closed = True
        self._release()

    def _release(self) -> None:
        close = getattr(self.kernel, "close", None)  # a banded kernel's threads or shared memory
        if close is not None:
            close()
        for hook in self.releases:
            hook()
        self.releases = []

    def close(self) -> RunResult:
        """The counts so far; ``outputs`` hold what ``feed_all`` kept of the open step (``feed`` returned every estimate)."""
        if self._closed:
            raise BackendError("stream is closed")
        self._closed = True
        kernel, names = self.kernel, self.pipeline.names
        fmt = kernel.config.fixed
        try:
            counts = {
                names[0]: input_counts(self._events_in, kernel.accepted, kernel.drops),
                names[1]: {"spikes": kernel.tot_spikes},
                names[2]: {name: int(c) for name, c in zip(OUTCOMES, kernel.outcomes)},
                names[3]: {}}
        finally:
            with self.clock.aside():  # stopping threads or worker processes: not the network's time
                self._release()
        counts = {name: counts[name] for name in self.order}
        outputs = {self.depth_name: canonical(self._held.pop(self.depth_name, np.empty(0, DEPTH_DTYPE)))}
        if self.record_tot:
            outputs[self.tot_name] = canonical(self._held.pop(self.tot_name, np.empty(0, TOT_DTYPE)))
        t0, last = self.t0_us if self.t0_us is not None else 0, self._last_event_us
        last_step = (last - t0) // self.timestep_us if last is not None and last >= t0 else -1
        # steps a promise (until_us) completed past the last event's count too, as a model-by-model stream's
        latest = self._latest_us
        promised = (latest - t0) // self.timestep_us if latest is not None and latest >= t0 else 0
        return RunResult.of(
            self.pipeline.network, self.backend, outputs, counts,
            steps=max(last_step + 1 + self.pipeline.latency_steps, promised), t0_us=t0, timestep_us=self.timestep_us,
            latency={name: self.pipeline.latency[name] for name in outputs},
            extra={**({"frac_bits": fmt.frac_bits, "payload_bits": fmt.payload_bits} if fmt else {}),
                   **getattr(kernel, "facts", {})}).timed_by(self.clock)
