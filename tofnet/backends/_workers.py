"""The worker side of the multiproc backend: one spawned OS process holding some cores' state.

A worker owns the event-driven kernel state (``tofnet.kernels.region``) of its
regions (a region is the pixels one time-of-travel core and one depth core share) and
nothing else. It answers messages from the host, in order, on one pipe:

=================================  ==============================================
host -> worker                     worker -> host
=================================  ==============================================
(on start)                         ("ready", pid)
("start", config, t0_us, regions, ("started",)
 halos, record_tot)
("chunk", seq, steps, x, y, p,     ("chunk", seq, depth, tot)
 velocity, first_update)
("finish",)                        ("finished", rejected[3], tot_spikes)
("fault", kind)                    (nothing; test hook, see ``_FAULTS``)
("stop",) or end of file           (exits)
=================================  ==============================================

Any exception while handling a message is answered with ``("error", traceback_text)``;
the host turns it into a ``BackendError`` and shuts every worker down. The module keeps
its imports light so that a spawned interpreter starts fast.
"""

from __future__ import annotations

import os
import signal
import time
import traceback

import numpy as np

#: Test hooks armed with ``("fault", kind)``; each fires when the next chunk arrives.
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
    try:
        conn.send(("error", text))
    except (BrokenPipeError, OSError):
        pass


def _warm_up() -> None:
    """Import the kernel and compile it (or load numba's cache) before reporting ready.

    The host's startup timeout covers this; chunk timeouts then measure only real work.
    """
    from tofnet.kernels.fixed_point import FixedPointFormat
    from tofnet.kernels.region import KernelConfig, Region, TimeOfTravelKernel

    config = KernelConfig((2, 1), 1e-3, 1, 8, 0.05, 20.0, 1, True, 30, (200.0, 200.0, 0.0, 0.0),
                          FixedPointFormat())
    kernel = TimeOfTravelKernel(config, Region(0, 2, 0, 1))
    kernel.process(np.array([0, 3]), np.array([0, 1]), np.array([0, 0]), np.array([1, 1]),
                   np.array([[-0.5, 0.0, 0.0]] * 8), 0, record_tot=True)


class _Worker:
    """The state of one worker between messages: one kernel per region of the current run."""

    def __init__(self, index: int):
        self.index = index
        self.kernels: list = []
        self.halos: list = []
        self.record_tot = False
        self.fault: str | None = None

    def handle(self, message: tuple):
        kind = message[0]
        if kind == "start":
            return self._start(*message[1:])
        if kind == "chunk":
            return self._chunk(*message[1:])
        if kind == "finish":
            return self._finish()
        if kind == "fault":
            if message[1] not in _FAULTS:
                raise ValueError(f"unknown fault {message[1]!r}; expected one of {_FAULTS}")
            self.fault = message[1]
            return None
        raise ValueError(f"unknown message {kind!r}")

    def _start(self, config, t0_us: int, regions, halos, record_tot: bool):
        from tofnet.kernels.region import TimeOfTravelKernel

        self.kernels = [TimeOfTravelKernel(config, region, t0_us) for region in regions]
        self.halos = list(halos)
        self.record_tot = bool(record_tot)
        return ("started",)

    def _chunk(self, seq: int, steps, xs, ys, ps, velocity, first_update: int):
        if self.fault is not None:
            self._fire_fault()
        from tofnet.compiler.partition import rects_mask

        parts = []
        for kernel, halo in zip(self.kernels, self.halos):
            # Only the spikes the compiled mapping routes to this region's core (its halo).
            sel = rects_mask(halo, xs, ys)
            if not sel.any():
                continue
            parts.append(kernel.process(steps[sel], xs[sel], ys[sel], ps[sel], velocity, first_update,
                                        record_tot=self.record_tot))
        depth = np.concatenate([o.depth for o in parts]) if parts else None
        tot = np.concatenate([o.tot for o in parts]) if parts and self.record_tot else None
        return ("chunk", seq, depth, tot)

    def _finish(self):
        rejected = np.zeros(3, dtype=np.int64)
        tot_spikes = 0
        for kernel in self.kernels:
            rejected += kernel.rejected
            tot_spikes += kernel.tot_spikes
        self.kernels = []
        return ("finished", rejected, tot_spikes)

    def _fire_fault(self) -> None:
        fault, self.fault = self.fault, None
        if fault == "raise":
            raise InjectedFault(f"fault injected into worker {self.index} (test hook)")
        if fault == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        if fault == "hang":
            while True:  # until the host's timeout terminates this process
                time.sleep(1.0)
