"""Backends that run every model in this process: ``reference``, ``float`` and ``fixed``.

A run is a stream (``open_stream``) fed the recording in packets, so memory does not grow
with the recording (apart from the outputs ``run`` collects). ``float`` and ``fixed`` run
the paper's chain through the fused kernel when they recognise it (``fusion.paper_chain``;
``fuse=False`` turns that off); every other graph runs model by model.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from tofnet.backends.bands import BandedKernel, band_placer, resolve_workers, sampled_row_load, threads_for
from tofnet.backends.base import Backend, ProgressCallback, RunResult, payloads_of
from tofnet.backends.fusion import FusedStream, PipelineParams, paper_chain
from tofnet.backends.graph import GraphExecutor, canonical, resolve_probes, sinks_of
from tofnet.backends.runtime import clock_of, start_time_us
from tofnet.backends.stream import GraphStream, packet_events_for, run_in_packets
from tofnet.compiler.bands import input_reach, plan_bands
from tofnet.compiler.compiled import network_of
from tofnet.core.network import Network
from tofnet.errors import BackendError, quote
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE, TOT_DTYPE
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS, FixedPointFormat
from tofnet.io.recording import Intrinsics, Recording, VelocitySource, as_velocity_source

#: Initial size of a fused run's result buffer in estimates (at most one per event); 4M x 28 B
#: of address space, resident only where written.
RESULT_CAPACITY = 1 << 22


def binding(recording: Recording | None, intrinsics: Intrinsics | None,
            velocity_source: VelocitySource | None, network: Network | None = None) -> Recording:
    """What a stream knows about the camera: a recording's metadata, or the pieces given
    (``velocity_source``: a ``VelocitySource`` or ``(tx, ty, tz)`` m/s). With ``network``, a
    recording that declares its sensor size must hold every process's (``check_sensor_fits``)."""
    if recording is not None:
        if network is not None:
            check_sensor_fits(network, recording)
        return recording
    if velocity_source is not None:
        velocity_source = as_velocity_source(velocity_source)
    return Recording(np.empty(0, EVENT_DTYPE), intrinsics=intrinsics, trajectory=velocity_source, source="the stream")


def check_sensor_fits(network: Network, recording: Recording) -> None:
    """Refuse a process sized larger than the sensor the recording declares (a mix-up of spec and
    recording: its edge pixels would never see an event, silently). A smaller process is a crop:
    the events outside it are dropped and counted (``out_of_bounds``)."""
    if recording.sensor_size is None:
        return
    width, height = recording.sensor_size
    for process in network.processes:
        size = process.sensor_size
        if size is not None and (size[0] > width or size[1] > height):
            raise BackendError(f"sensor size mismatch: process '{process.name}' is {size[0]}x{size[1]} px and "
                               f"{recording.source} declares {width}x{height} px; size the network to the "
                               f"recording (e.g. --sensor-size {width}x{height})")


class LocalBackend(Backend):
    """Runs the models of ``family`` in this process, model by model (``GraphExecutor``)."""

    #: Whether this backend may run a recognised chain through a fused kernel.
    fuses = False
    capabilities = frozenset({"stream", "bands"})
    run_modes = (("fused", {"fuse": True}), ("unfused", {"fuse": False}))

    def __init__(self, packet_events: int | None = None, fuse: bool = True, workers: int | str = 1):
        if not isinstance(fuse, (bool, np.bool_)):  # a spec's ``fuse: 3`` or ``"no"`` was taken as true
            raise BackendError(f"{self.name or 'backend'}: fuse: expected true or false, got {quote(fuse)}")
        self.fuse = bool(fuse)
        #: Bands the sensor is cut into (``tofnet.backends.bands``), run on at most one thread per CPU.
        self.workers = resolve_workers(workers, f"{self.name or 'backend'}: workers")
        #: Events per packet of ``run`` (None: 2^17 with one worker, 2^19 with several).
        self.packet_events = packet_events_for(packet_events, self.workers, self.name or "backend")

    def _format(self) -> FixedPointFormat | None:
        """The depth's fixed-point format, by ``arithmetic``: the default one for a backend whose
        arithmetic is ``fixed`` (a subclass setting only ``arithmetic``/``family`` computes in fixed
        point as it says), None for float."""
        return FixedPointFormat(DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS) if self.arithmetic == "fixed" else None

    def open_stream(self, compiled, *, recording: Recording | None = None, intrinsics: Intrinsics | None = None,
                    velocity_source: VelocitySource | tuple[float, float, float] | None = None,
                    t0_us: int | None = None,
                    probes: Iterable[str] = (), record_tot: bool = False,
                    fuse: bool | None = None) -> GraphStream | FusedStream:
        """A stream running ``compiled`` (a ``CompiledNetwork`` or ``Network``).

        What the processes need to know about the camera comes from ``recording`` (its
        metadata) or from ``intrinsics`` and ``velocity_source``. ``t0_us`` None: the
        network's ``t0``, else the first event fed. ``probes``: output ports to return
        besides the sinks (``record_tot``: every time-of-travel counter port). ``fuse``
        overrides the backend's choice (False: model by model, as sessions need).
        """
        network = network_of(compiled)
        known = binding(recording, intrinsics, velocity_source, network)
        clock = clock_of(network)
        t0 = clock.t0_us if t0_us is None else int(t0_us)
        probes = resolve_probes(network, probes, record_tot)
        if self.fuses and (self.fuse if fuse is None else fuse):
            pipeline = paper_chain(network, self.family, probes)
            if pipeline is not None:
                return self._fused_stream(network, pipeline, known, t0, f"{pipeline.names[1]}.counts" in probes)
        bands = self._bands(network, known)
        place, pool, facts = band_placer(bands, threads_for(len(bands))) if len(bands) > 1 else (None, None, {})

        def build(start_us: int) -> GraphExecutor:
            if place is None:  # a subclass's own executor need not take bands (lava)
                return self._executor(network, start_us, clock.timestep_us, known, probes)
            return self._executor(network, start_us, clock.timestep_us, known, probes, place)

        sinks = sinks_of(network)
        stream = GraphStream(self.name, build, t0, clock.timestep_us, sinks,
                             payloads_of(network, list(dict.fromkeys(sinks + probes))))
        if pool is not None:
            stream.extra.update(facts)
            stream.releases.append(pool.close)
        if stream.executor is None:  # check models and bindings now, not at the first event: set-up, not running
            with stream.clock.aside():
                build(0)
        fmt = self._format()
        if fmt is not None:
            stream.extra.update(frac_bits=fmt.frac_bits, payload_bits=fmt.payload_bits)
        return stream

    def _executor(self, network: Network, t0_us: int, timestep_us: int, recording: Recording,
                  probes: list[str], place=None) -> GraphExecutor:
        """What runs the models of a stream: a ``GraphExecutor`` here (the lava backend gives its own);
        ``place``: builds the models of bands (``band_placer``)."""
        from tofnet.backends.registry import backends_by_family
        return GraphExecutor(network, family=self.family, backend=self.name, t0_us=t0_us, timestep_us=timestep_us,
                             recording=recording, fixed_format=self._format(), probes=probes,
                             backends_by_family=backends_by_family, place=place)

    def _fused_stream(self, network: Network, pipeline: PipelineParams, known: Recording, t0_us: int | None,
                      record_tot: bool) -> FusedStream:
        source = pipeline.velocity_source(known)
        config = pipeline.kernel_config(known, self._format())
        bands = self._bands(network, known)
        kernel = None
        if len(bands) > 1:
            kernel = BandedKernel(config, bands, input_reach(network), threads_for(len(bands)), t0_us or 0)
        return FusedStream(self.name, config, pipeline, source, t0_us, record_tot, order=[p.name for p in
                                                                                       network.processes],
                           kernel=kernel)

    def _bands(self, network: Network, known: Recording) -> list[tuple[int, int]]:
        """The rows of each band: balanced by the recording's events per row when it has events."""
        if self.workers < 2:
            return [(0, network.sensor_size[1])]
        height = network.sensor_size[1]
        return plan_bands(height, self.workers, sampled_row_load(known.events, height))

    def run(self, compiled, recording: Recording, *, probes: Iterable[str] = (), record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        network = network_of(compiled)
        t0 = start_time_us(clock_of(network).t0_us, recording)
        stream = self.open_stream(network, recording=recording, t0_us=t0, probes=probes, record_tot=record_tot)
        if isinstance(stream, FusedStream):
            stream.expect_whole_run()
            return run_fused(stream, recording.events, self.packet_events, progress)
        return run_in_packets(stream, recording.events, self.packet_events, progress)


def run_fused(stream: FusedStream, events: np.ndarray, packet_events: int,
              progress: ProgressCallback | None) -> RunResult:
    """Feed ``events`` to a fused stream in packets, the kernel writing the estimates in place; timed by
    the stream's clock (its set-up apart)."""
    total = len(events)
    # a kernel whose bands run in other processes has them write the estimates to memory it shares
    depth = _Collector(DEPTH_DTYPE, min(total, RESULT_CAPACITY), getattr(stream.kernel, "allocate", None))
    tot = _Collector(TOT_DTYPE, 0)
    seams = []  # where one packet's estimates end: a step may go on in the next packet's
    ahead = getattr(stream.kernel, "next_packet", None)  # a kernel that copies the next packet meanwhile
    for lo in range(0, total, packet_events):
        packet = events[lo:lo + packet_events]
        if ahead is not None:
            ahead(events[lo + packet_events:lo + 2 * packet_events])
        buffer, offset = depth.reserve(len(packet))
        out = stream.feed_into(packet, buffer, offset)  # the kernel writes the estimates in place
        if out is not None:
            seams.append(offset)
            depth.commit(len(out.depth))
            if stream.record_tot:
                tot.add(out.tot)
        if progress is not None:
            progress(min(lo + packet_events, total), total)
    result = stream.close()
    result.outputs[stream.depth_name] = stream.kernel.join_packets(depth.array(), seams)
    if stream.record_tot:
        result.outputs[stream.tot_name] = canonical(tot.array())
    return result.timed_by(stream.clock)


class _Collector:
    """Appends record arrays into one buffer that grows geometrically (one copy per record);
    ``allocate(count, dtype)`` makes each buffer (default ``np.empty``)."""

    def __init__(self, dtype: np.dtype, capacity: int, allocate=None):
        self._allocate = allocate or np.empty
        self._buffer = self._allocate(capacity, dtype)
        self._size = 0

    def reserve(self, n: int) -> tuple[np.ndarray, int]:
        """``(buffer, offset)`` with room for ``n`` records at ``offset``; ``commit`` how many were written."""
        end = self._size + n
        if end > len(self._buffer):
            grown = self._allocate(max(end, 2 * len(self._buffer)), self._buffer.dtype)
            raw = np.dtype((np.void, grown.dtype.itemsize))
            grown[:self._size].view(raw)[:] = self._buffer[:self._size].view(raw)
            self._buffer = grown
        return self._buffer, self._size

    def commit(self, n: int) -> None:
        self._size += n

    def add(self, part: np.ndarray) -> None:
        buffer, offset = self.reserve(len(part))
        raw = np.dtype((np.void, part.dtype.itemsize))  # packed records copy field by field, bytes do not
        buffer[offset:offset + len(part)].view(raw)[:] = part.view(raw)
        self.commit(len(part))

    def array(self) -> np.ndarray:
        """The records so far. A view: pages of the buffer never written are never resident."""
        return self._buffer[:self._size]
