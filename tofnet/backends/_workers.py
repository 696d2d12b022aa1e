"""The worker side of the multiproc backend: one spawned OS process holding some cores' models.

A worker owns model instances (one per compiled core it runs, see
``tofnet.backends.remote``) and nothing else. It answers messages from the host, in
order, on one pipe:

=================================  ==============================================
host -> worker                     worker -> host
=================================  ==============================================
(on start)                         ("ready", pid)
("build", specs)                   ("built",)
("run", items, first, end)         ("run", [(key, outputs), ...])
("counts", keys)                   ("counts", [counts of each key])
("get", keys, var, step)           ("get", [the variable's values of each key])
("set", keys, var, value, step)    ("set", [None, ...])
("param", keys, name, value)       ("param", [None, ...])
("band", spec)                     ("band",)   (shared-memory bands: ``_band_worker``)
("band_run" | "band_promise" | "band_counts" | "band_map", ...)   (the same kind, answered)
("finish",)                        ("finished",)
("fault", kind)                    (nothing; test hook, see ``_FAULTS``)
("stop",) or end of file           (exits)
=================================  ==============================================

``items`` pairs each model key with its inputs for steps ``[first, end)``. Any
exception while handling a message is answered with ``("error", traceback_text)``; the
host turns it into a ``BackendError`` and shuts every worker down. The module keeps its
imports light so that a spawned interpreter starts fast.
"""

from __future__ import annotations

import os
import signal
import sys
import time
import traceback

import numpy as np

from tofnet.errors import TofnetError

#: Test hooks armed with ``("fault", kind)``; each fires when the next ``run`` arrives.
_FAULTS = ("raise", "kill", "hang")


class InjectedFault(RuntimeError):
    """Raised by the ``raise`` test hook (proves worker tracebacks reach the caller)."""


def worker_main(conn, index: int) -> None:
    """Entry point of a spawned worker; returns (and the process exits) on ``stop`` or EOF."""
    # Ctrl-C in a terminal reaches the whole process group; the host handles it and shuts
    # the workers down, so a worker must not die half-way with its own traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _warm_up()
        conn.send(("ready", os.getpid()))
    except Exception:
        _reply_error(conn, index)
        return
    worker = _Worker(index)
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return  # the host went away: nothing left to serve
        if message[0] == "stop":
            return
        try:
            reply = worker.handle(message)
        except Exception:
            _reply_error(conn, index)
            continue
        if reply is not None:
            try:
                conn.send(reply)
            except (BrokenPipeError, OSError):
                return


def _reply_error(conn, index: int) -> None:
    text = f"worker {index} (pid {os.getpid()}):\n{traceback.format_exc()}"
    error = sys.exc_info()[1]
    refusal = str(error) if isinstance(error, TofnetError) else None  # the user's mistake: its one line
    try:
        conn.send(("error", text, refusal))
    except (BrokenPipeError, OSError):
        pass


def _warm_up() -> None:
    """Import the built-in core models' kernels and compile them (or load numba's cache) before
    reporting ready: the host's start-up timeout covers this; run timeouts measure real work."""
    from tofnet.events import TOT_DTYPE
    from tofnet.kernels.fixed_point import FixedPointFormat
    from tofnet.kernels.kernel_config import DepthSettings, UnitSettings
    from tofnet.kernels.region import KernelConfig, TimeOfTravelKernel

    units = UnitSettings(distance=1, counter_bits=8)
    units_alone = TimeOfTravelKernel(KernelConfig(sensor_size=(2, 1), timestep_us=1000, units=units))
    out = units_alone.process(np.array([0, 3]), np.array([0, 1]), np.array([0, 0]), np.array([1, 1]),
                              np.zeros((0, 3)), 0, record_tot=True)
    neurons = DepthSettings(min_depth=0.05, max_depth=20.0, per_pixel=True, patch_size=30,
                            intrinsics=(200.0, 200.0, 0.0, 0.0))
    depth = TimeOfTravelKernel(KernelConfig(sensor_size=(2, 1), timestep_us=1000, units=units, depth=neurons,
                                            fixed=FixedPointFormat()))
    velocity = np.zeros(1, dtype=[("step", "<i8"), ("tx", "<f8"), ("ty", "<f8"), ("tz", "<f8")])
    depth.process_counts(out.tot if len(out.tot) else np.empty(0, TOT_DTYPE), velocity)


class _Worker:
    """The state of one worker between messages: the model instances of the current run."""

    def __init__(self, index: int):
        self.index = index
        self.models: dict = {}
        self.band = None  # the fused kernel of this worker's band (shared-memory mode)
        self.fault: str | None = None

    def handle(self, message: tuple):
        kind = message[0]
        if kind == "build":
            self.models = {spec.key: spec.build() for spec in message[1]}
            return ("built",)
        if kind == "run":
            if self.fault is not None:
                self._fire_fault()
            _, items, first, end = message
            from tofnet.models.contract import run_model  # each instance's failure names its process and step
            return ("run", [(key, run_model(self.models[key].process, self.models[key], first, end, inputs))
                            for key, inputs in items])
        if kind == "counts":
            return ("counts", [self.models[key].counts() for key in message[1]])
        if kind == "get":
            _, keys, name, step = message
            return ("get", [self.models[key].get_var(name, step) for key in keys])
        if kind == "set":
            _, keys, name, value, step = message
            return ("set", [self.models[key].set_var(name, value, step) for key in keys])
        if kind == "param":
            _, keys, name, value = message
            from tofnet.models.base import apply_param
            apply_param([(self.models[key].process, self.models[key]) for key in keys], name, value)
            return ("param", [None] * len(keys))
        if kind == "band":
            from tofnet.backends._band_worker import BandWorker
            self._drop_band()
            self.band = BandWorker(message[1])
            return ("band",)
        if kind.startswith("band_"):
            if self.fault is not None and kind == "band_run":
                self._fire_fault()
            return self.band.handle(message)
        if kind == "finish":
            self.models = {}
            self._drop_band()
            return ("finished",)
        if kind == "fault":
            if message[1] not in _FAULTS:
                raise ValueError(f"unknown fault {message[1]!r}; expected one of {_FAULTS}")
            self.fault = message[1]
            return None
        raise ValueError(f"unknown message {kind!r}")

    def _drop_band(self) -> None:
        if self.band is not None:
            self.band.close()
            self.band = None

    def _fire_fault(self) -> None:
        fault, self.fault = self.fault, None
        if fault == "raise":
            raise InjectedFault(f"fault injected into worker {self.index} (test hook)")
        if fault == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        if fault == "hang":
            while True:  # until the host's timeout terminates this process
                time.sleep(1.0)
