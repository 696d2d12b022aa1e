"""Run control, Lava style: run a network some steps at a time, read and set its state in between.

    with Session(network, recording, backend="fixed") as s:
        s.run(steps=10)                              # Lava: proc.run(RunSteps(10))
        s.get("time_of_travel.counter")              # Lava: var.get()   -> [4, H, W] at step 10
        s.set("input.refractory", "30ms")            # a parameter, from step 10 on
        s.run(until=0.5)                             # to 0.5 s after t0
        result = s.finish()                          # the rest; equal to one uninterrupted run

The session keeps the network's state between runs: running in chunks of any size gives
exactly the records of one run (tests/test_session.py, every backend). It runs the models
one by one (the fused kernel only with ``fuse=True``, for a live source), so every process's
state can be read. Docs: docs/sessions.md.
"""

from __future__ import annotations

import copy
from typing import Any, Iterable

import numpy as np

from tofnet.backends.base import Backend, RunResult
from tofnet.backends.registry import get_backend
from tofnet.backends.runtime import clock_of, start_time_us
from tofnet.backends.stream import Collected
from tofnet.core.network import Network
from tofnet.errors import BackendError, TofnetError, UnsupportedError
from tofnet.events import EVENT_DTYPE, MAX_TIME_US
from tofnet.io.recording import Recording
from tofnet.monitor import Monitor


class Session:
    """A network open on a backend and a recording (or a live source), advanced on request.

    ``network``: a ``Network`` or ``CompiledNetwork``; ``recording``: the events to step
    through (None: a live source, give ``intrinsics``/``velocity_source`` and ``feed``
    events); ``backend``: a name, a ``Backend``, or an open ``MultiprocSession`` (whose
    workers it then uses and leaves running); ``probes``: output ports to keep besides
    the sinks (``record_tot``: every time-of-travel counter port); ``monitors``: ``Monitor``
    objects or their strings (``"proc.var@x,y"``); ``keep_outputs`` False: what ``run``/``feed``
    return is not also kept for ``outputs()`` and ``finish()`` (a live source running for hours).
    ``step`` is the next step to run: every step before it has run. The session works on
    its own copy of the network: ``set`` never changes the caller's processes. ``camera``: a
    live source's metadata (a ``Recording`` without events: intrinsics, poses, IMU), instead of
    ``intrinsics``/``velocity_source``, so that a process the IMU drives binds as in a run.
    ``fuse`` True (a live source without monitors, as ``tofnet live``): the backend may run the paper's
    chain through its fused kernel, the same records several times faster (docs/live.md), with no process state
    to read: ``get``, ``set``, ``step`` and ``counts`` refuse until ``finish`` (docs/sessions.md).
    """

    def __init__(self, network, recording: Recording | None = None, *, backend: str | Backend = "fixed",
                 backend_options: dict | None = None, compile_options: dict | None = None,
                 probes: Iterable[str] = (), record_tot: bool = False, monitors: Iterable[Monitor | str] = (),
                 intrinsics=None, velocity_source=None, t0_us: int | None = None, keep_outputs: bool = True,
                 camera: Recording | None = None, fuse: bool = False):
        from tofnet.compiler import CompiledNetwork, compile_network

        compiled = network if isinstance(network, CompiledNetwork) else compile_network(
            network, **(compile_options or {}))
        self.compiled = copy.deepcopy(compiled)  # set() changes parameters: of this session's copy only
        self.network: Network = self.compiled.network
        self.recording = recording
        self.backend = get_backend(backend, **(backend_options or {})) if isinstance(backend, str) else backend
        self.monitors = _monitors(monitors)
        if fuse and (recording is not None or self.monitors):
            raise TofnetError("session: fuse=True is for a live source without monitors (a fused kernel keeps no "
                              "process state to step through or record)")
        self._fuse = bool(fuse)
        ports = self._bind_monitors(self.monitors)
        clock = clock_of(self.network)
        if recording is not None and t0_us is None:
            t0_us = start_time_us(clock.t0_us, recording)
        self._resource = None
        if camera is not None and (recording is not None or intrinsics is not None or velocity_source is not None):
            raise TofnetError("session: camera= describes a live source's camera whole; give it alone, without a "
                              "recording, intrinsics or velocity_source")
        options = dict(recording=recording if camera is None else camera, intrinsics=intrinsics,
                       velocity_source=velocity_source, t0_us=t0_us,
                       probes=list(dict.fromkeys([*probes, *ports])), record_tot=record_tot)
        self.stream = self._open(options)
        self.timestep_us = self.stream.timestep_us
        self._cursor = 0  # next event of the recording to feed
        self._collected = Collected()
        self._keep_outputs = keep_outputs
        self._state = "open"
        self._sample()

    # -- opening and closing --------------------------------------------------------------------
    def _open(self, options: dict):
        backend = self.backend
        capabilities = getattr(backend, "capabilities", frozenset())
        if "open session" in capabilities:
            # an open multiproc session: its workers, not ours
            return backend.open_stream(self.compiled, fuse=self._fuse, **options)
        if "workers" in capabilities:  # multiproc: workers kept for the session
            self._resource = backend.session(self.compiled)
            self._resource.open()
            try:
                return self._resource.open_stream(fuse=self._fuse, **options)
            except BaseException:
                self._resource.close(graceful=False)
                raise
        if "stream" not in capabilities:
            raise UnsupportedError(f"backend {getattr(backend, 'name', type(backend).__name__)!r} offers no "
                                   f"streams, which a session needs (Backend.capabilities has no 'stream')")
        return backend.open_stream(self.compiled, fuse=None if self._fuse else False, **options)

    def _bind_monitors(self, monitors: list[Monitor]) -> list[str]:
        """Check each monitor's target and pixels (inside the process's sensor); the ports among them
        become probes."""
        ports = []
        for monitor in monitors:
            process = self.network.process(monitor.process)
            variables = [v.name for v in type(process).vars]
            if monitor.name in variables:
                monitor.kind = "var"
            elif monitor.name in process.ports:
                monitor.kind = "port"
                ports.append(monitor.target)
            else:
                raise TofnetError(f"monitor {monitor.target}: {process.name} ({type(process).__name__}) has no "
                                  f"variable or port {monitor.name!r}; variables: {', '.join(variables) or 'none'}; "
                                  f"ports: {', '.join(process.ports)}")
            width, height = process.sensor_size
            for x, y in monitor.pixels or ():
                if not (x < width and y < height):
                    raise TofnetError(f"monitor {monitor.target}: pixel ({x}, {y}) is outside the "
                                      f"{width}x{height} sensor (x 0..{width - 1}, y 0..{height - 1})")
        return ports

    def add_monitors(self, monitors: Iterable[Monitor | str]) -> None:
        """Start recording more monitors from ``step`` on (a port must be a sink or probed since the
        session opened). Nothing is added when one of them is refused."""
        if self.fused:
            raise TofnetError("session: it runs the fused kernel (fuse=True), which keeps no process state to "
                              "monitor; open it with fuse=False for monitors")
        added = _monitors(monitors)
        ports = self._bind_monitors(added)
        wanted = set(self.stream.sinks) | set(self.stream.payloads)
        missing = [p for p in ports if p not in wanted]
        if missing:
            raise TofnetError(f"monitor {missing[0]}: that port was not probed when the session opened; "
                              "pass it in probes= (or as a monitor) to Session()")
        self.monitors = self.monitors + added
        self._sample()

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def stop(self) -> None:
        """Release what the backend holds (multiproc workers); the session cannot run after this."""
        if self._resource is not None:
            resource, self._resource = self._resource, None
            resource.close(graceful=self._state != "failed")
        if self._state == "open":
            self._state = "stopped"

    # -- where it is ----------------------------------------------------------------------------
    @property
    def fused(self) -> bool:
        """Whether the backend runs the network through its fused kernel (``fuse=True``): no process state."""
        return not hasattr(self.stream, "executor")

    def output_latency(self, name: str) -> int:
        """Steps from an event's step to the step its records on output ``name`` are stamped."""
        latency = self.stream.pipeline.latency if self.fused else self.executor.latency
        if name not in latency:
            raise TofnetError(f"session: no output {name!r}; outputs: {', '.join(latency)}")
        return latency[name]

    @property
    def executor(self):
        if self.fused:
            raise BackendError("session: it runs the fused kernel (fuse=True), which keeps no process state to "
                               "read, set or count before finish(); open it with fuse=False for that")
        if self.stream.executor is None:
            raise BackendError("session: no event has come yet, so step 0 has no start time (feed events first)")
        return self.stream.executor

    @property
    def step(self) -> int:
        """The next step to run (every step before it has run)."""
        if self.fused:
            return self.executor.clock  # refuses: a fused kernel runs no steps of its own to count
        return self.stream.executor.clock if self.stream.executor is not None else 0

    @property
    def events_fed(self) -> int:
        """Events of the recording fed so far (a progress's count)."""
        return self._cursor

    @property
    def time(self) -> float:
        """Seconds from step 0's start to the start of ``step``."""
        return self.step * self.timestep_us * 1e-6

    def _check_open(self) -> None:
        if self._state != "open":
            raise BackendError(f"session is {self._state}; open a new one")

    # -- running --------------------------------------------------------------------------------
    def run(self, steps: int | None = None, *, until: float | None = None) -> dict[str, np.ndarray]:
        """Run ``steps`` more steps, or up to ``until`` seconds after step 0's start, or (neither)
        to the step of the recording's last event. Returns what sinks and probes sent meanwhile."""
        self._check_open()
        if self.recording is None:
            raise BackendError("session on a live source: use feed(events, until_us=...)")
        if steps is not None and until is not None:
            raise TofnetError("run: give steps or until, not both")
        t0, dt = self.stream.t0_us, self.timestep_us
        if steps is not None:
            if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
                raise TofnetError(f"run: steps must be a whole number >= 0, got {str(steps)[:40]!r}")
            target = self.step + int(steps)
            self._check_step(target, f"run: steps={int(steps)}")
        elif until is not None:
            target = max(self.step, self._until_step(until))
        else:
            t = self.recording.events["t"]
            target = max(self.step, (int(t[-1]) - t0) // dt + 1 if len(t) else 0)
        out = Collected()
        for boundary in self._boundaries(target):
            events = self.recording.events
            end = int(np.searchsorted(events["t"], t0 + boundary * dt, side="left"))
            out.add(self._guard(lambda: self.stream.feed_all(events[self._cursor:end], until_us=t0 + boundary * dt)))
            self._cursor = end
            self._sample()
        produced = out.joined(list(out.parts), lambda name: np.empty(0))
        self._keep(produced)
        return produced

    def feed(self, events: np.ndarray, until_us: int | None = None) -> dict[str, np.ndarray]:
        """Live source: feed events (time order); the records of the steps they completed."""
        self._check_open()
        if self.recording is not None:
            raise BackendError("session on a recording: use run(...); feed() is for a live source "
                               "(Session(network, intrinsics=..., velocity_source=...))")
        self._check_packet(events, until_us)
        produced = self._guard(lambda: self.stream.feed_all(events, until_us))
        self._keep(produced)
        self._sample()
        return produced

    def _check_packet(self, events, until_us) -> None:
        """Refuse, leaving the session as it was, a packet the stream would refuse (a refusal is
        not a failure: the session stays open)."""
        check = getattr(self.stream, "check", None)
        if check is not None:
            check(events, until_us)
        else:
            self.stream._admit(events, until_us)

    def _keep(self, produced: dict[str, np.ndarray]) -> None:
        if self._keep_outputs:
            self._collected.add(produced)
        for m in self.monitors:
            if m.kind == "port" and m.target in produced and len(produced[m.target]):
                m.record_port(produced[m.target])

    def _until_step(self, until) -> int:
        """The step ``until`` seconds after step 0's start ends in, checked."""
        if isinstance(until, bool) or not isinstance(until, (int, float, np.integer, np.floating)) or \
                not np.isfinite(until):
            raise TofnetError(f"run: until must be a finite number of seconds, got {str(until)[:40]!r}")
        if abs(until) >= MAX_TIME_US * 1e-6:
            raise TofnetError(f"run: until={float(until):.6g} s is out of the time range (|t| < 2**61 µs)")
        target = int(np.ceil(float(until) * 1e6 / self.timestep_us - 1e-9))
        self._check_step(target, f"run: until={float(until):.6g} s")
        return target

    def _check_step(self, target: int, what: str) -> None:
        """Refuse a run whose end lies beyond the time range (|t| < 2**61 µs)."""
        end_us = self.stream.t0_us + target * self.timestep_us
        if end_us >= MAX_TIME_US:
            raise TofnetError(f"{what} ends at {end_us} µs, out of the time range (|t| < 2**61 µs)")

    def _boundaries(self, target: int) -> list[int]:
        """Where to stop on the way to ``target``: every sampling step of a variable monitor, and ``target``."""
        stops = {target}
        for m in self.monitors:
            if m.kind == "var":
                first = (self.step // m.every + 1) * m.every
                stops.update(range(first, target, m.every))
        return sorted(s for s in stops if s > self.step) or [target]

    def _guard(self, action):
        try:
            return action()
        except MemoryError:  # e.g. a promise far ahead: every step up to it runs at once
            self._state = "failed"
            self.stop()
            where = "the last packet" if self.fused else f"the steps from {self.step} on"
            raise BackendError(f"session: out of memory running {where}; run fewer steps "
                               "(or promise a nearer until_us) at a time; the session is failed") from None
        except BaseException:
            self._state = "failed"
            self.stop()
            raise

    def _sample(self) -> None:
        if not self.monitors or getattr(self.stream, "executor", None) is None:
            return
        step = self.step
        for m in self.monitors:
            if m.kind == "var" and step % m.every == 0 and (not m.steps or m.steps[-1] != step):
                m.record_var(step, self.get(m.target))

    def finish(self) -> RunResult:
        """Run what is left of the recording and the steps still in flight; the whole run's result
        (every output since the session opened, every count; ``keep_outputs`` False: the outputs of
        the steps run now only). The session ends."""
        self._check_open()
        now = Collected()  # what this call runs: the result's outputs when the session keeps none
        if self.recording is not None:
            now.add(self.run())
        self._drain_sampled(now)
        result = self._guard(self.stream.close)
        self._keep(result.outputs)
        now.add(result.outputs)
        result.outputs = (self._collected if self._keep_outputs else now).joined(result.payloads, self.stream._empty)
        self._state = "finished"
        self.stop()
        return result

    def _drain_sampled(self, produced: Collected) -> None:
        """Run the steps ``close`` would run (the outputs still in flight) here, where the variable
        monitors sample the start of each as of every step before (no events come: each is the
        same step run); a sample is of a step that ran, so none at the end. Their records go to
        ``produced`` too."""
        end = self.stream.end_step() if hasattr(self.stream, "end_step") else None
        if end is None or end <= self.step or not any(m.kind == "var" for m in self.monitors):
            return
        nothing = np.empty(0, EVENT_DTYPE)
        for boundary in [b for b in self._boundaries(end) if b < end]:  # close runs the rest
            until_us = self.stream.t0_us + boundary * self.timestep_us
            records = self._guard(lambda: self.stream.feed_all(nothing, until_us=until_us))
            self._keep(records)
            produced.add(records)
            self._sample()

    # -- state ----------------------------------------------------------------------------------
    def _split(self, name: str) -> tuple[Any, str]:
        process_name, _, item = str(name).partition(".")
        if not item:
            raise TofnetError(f"expected PROCESS.NAME (a variable or a parameter), got {name!r}")
        return self.network.process(process_name), item

    def get(self, name: str):
        """A variable at the start of ``step`` (``"time_of_travel.counter"``) or a parameter's value."""
        process, item = self._split(name)
        if any(v.name == item for v in type(process).vars):
            return self.executor.get_var(process.name, item)
        if item in process.values:
            return process.values[item]
        variables = ", ".join(v.name for v in type(process).vars) or "none"
        raise TofnetError(f"{name}: {process.name} ({type(process).__name__}) has no variable or parameter "
                          f"{item!r}; variables: {variables}; parameters: {', '.join(process.values)}")

    def set(self, name: str, value) -> None:
        """Set a variable (before ``step`` runs) or a parameter (from ``step`` on); see docs/sessions.md."""
        self._check_open()
        process, item = self._split(name)
        if any(v.name == item for v in type(process).vars):
            self.executor.set_var(process.name, item, value)
        else:
            self.executor.set_param(process.name, item, value)

    def outputs(self) -> dict[str, np.ndarray]:
        """Every record the sinks and probes sent so far."""
        return self._collected.joined(list(self._collected.parts), lambda name: np.empty(0))

    def counts(self) -> dict[str, dict[str, int]]:
        return self.executor.counts()


def _monitors(monitors: Iterable[Monitor | str]) -> list[Monitor]:
    """``Monitor`` objects from monitors or their strings (``"proc.var@x,y"``); one alone is one."""
    if isinstance(monitors, (Monitor, str)):
        monitors = [monitors]
    out = []
    for m in monitors:
        if not isinstance(m, (Monitor, str)):
            raise TofnetError(f"monitors: expected Monitor objects or strings 'PROCESS.VAR@X,Y', got "
                              f"{type(m).__name__}")
        out.append(m if isinstance(m, Monitor) else Monitor.parse(m))
    return out
