"""The host's end of one multiproc worker: a spawned process, a pipe, and waits that end.

Every wait is bounded and also watches the process itself (its ``sentinel``), so a
worker that dies is reported at once with its exit code or signal instead of leaving
the host blocked on a pipe that will never deliver (the failure Lava's users hit).
A large message goes through a small thread because it blocks in ``send`` until the worker
reads it; the host then only ever blocks in ``expect``, which has a timeout. A small one (every
message of a banded run's packet) is written at once when nothing is queued: every message but
a test's fault hook is answered before the next is sent, so the worker has read what came
before, and the hand-over to the thread would cost more than the write (docs/performance.md).
"""

from __future__ import annotations

import queue
import signal
import sys
import threading
import time
from multiprocessing.connection import wait
from multiprocessing.reduction import ForkingPickler

from tofnet.errors import BackendError

#: Seconds a graceful stop waits for a worker to exit before terminating it.
STOP_WAIT = 5.0
#: Seconds to wait after SIGTERM (then SIGKILL) before giving up on a worker.
KILL_WAIT = 5.0
#: Pickled messages up to this many bytes are written by the caller (one write, far below the pipe's room).
DIRECT_BYTES = 4000


class WorkerError(BackendError):
    """A worker that is alive answered with an error: its traceback in the message, or ``refusal``: the
    one-line message of a ``TofnetError`` it raised (a value the user gave refused, a model's failure)."""

    def __init__(self, message: str, refusal: str | None = None, traceback: str = ""):
        super().__init__(message)
        self.refusal = refusal
        #: The worker's traceback text, when the message is a refusal's one line.
        self.traceback = traceback


class WorkersRefused(WorkerError):
    """Workers that answered one message with errors (``refused`` of them) while ``answered`` others did
    what it asked (``answers(..., settle=True)``)."""

    def __init__(self, first: WorkerError, refused: int, answered: int):
        super().__init__(str(first), first.refusal, first.traceback)
        self.refused, self.answered = refused, answered


class Channel:
    """One worker process and the host's end of its pipe."""

    def __init__(self, ctx, index: int):
        from tofnet.backends._workers import worker_main

        self.index = index
        parent, child = ctx.Pipe(duplex=True)
        self.process = ctx.Process(target=worker_main, args=(child, index), name=f"tofnet-multiproc-{index}",
                                   daemon=True)
        try:
            self.process.start()
        except BaseException:
            parent.close()
            raise
        finally:
            child.close()  # only the worker holds its end now: its death closes the pipe
        self.conn = parent
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._queued = 0  # messages handed to the sending thread and not sent yet
        self._send_error: BaseException | None = None
        self._sender = threading.Thread(target=self._send_loop, name=f"tofnet-multiproc-send-{index}", daemon=True)
        self._sender.start()

    # -- talking ----------------------------------------------------------------------------
    def send(self, message: tuple) -> None:
        """Queue ``message`` for the worker (never blocks)."""
        if self._send_error is not None:
            raise self.failure("could not be sent to", f"({self._send_error})")
        data = bytes(ForkingPickler.dumps(message))  # what ``conn.send`` writes
        with self._lock:
            direct = not self._queued and len(data) <= DIRECT_BYTES
            if not direct:
                self._queued += 1
        if not direct:
            self._outbox.put(data)
            return
        try:
            self.conn.send_bytes(data)
        except (OSError, ValueError) as err:  # the worker died or the pipe was closed
            self._send_error = err
            raise self.failure("could not be sent to", f"({err})") from None

    def _send_loop(self) -> None:
        while True:
            data = self._outbox.get()
            if data is None:
                return
            try:
                self.conn.send_bytes(data)
            except (OSError, ValueError) as err:  # the worker died or the pipe was closed
                self._send_error = err
                return
            finally:
                with self._lock:
                    self._queued -= 1

    def expect(self, kind: str, timeout: float, doing: str, timeout_name: str = "timeout",
               limit: float | None = None, ready: list | None = None) -> tuple:
        """The worker's next message, which must be ``kind``; ``BackendError`` on an error reply,
        death of the worker, or no answer within ``timeout`` seconds (``limit``: the configured
        value to name in the error, when ``timeout`` is what remains of it). ``ready``: what a
        ``wait`` just returned that holds this worker's pipe or process (no second wait)."""
        if ready is None:
            ready = wait([self.conn, self.process.sentinel], timeout)
        if self.conn in ready:  # read first: a worker may report an error and then exit
            try:
                message = self.conn.recv()
            except (EOFError, OSError):
                raise self.failure("died", f"while {doing}") from None
        elif ready:
            raise self.failure("died", f"while {doing}")
        else:
            raise BackendError(f"multiproc worker {self.index} (pid {self.process.pid}) did not answer within "
                               f"{timeout if limit is None else limit:g} s while {doing}; all workers were stopped (raise the backend's "
                               f"{timeout_name} if the machine is just slow)")
        if message[0] == "error":
            refusal = message[2] if len(message) > 2 else None
            if refusal is not None:  # a TofnetError (a model's failure names its process and step): its one line
                raise WorkerError(f"multiproc worker {self.index} failed while {doing}: {refusal}", refusal,
                                  message[1])
            raise WorkerError(f"multiproc worker {self.index} failed while {doing}; its traceback:\n{message[1]}")
        if message[0] != kind:
            raise BackendError(f"multiproc worker {self.index} sent {message[0]!r} while {doing}, expected {kind!r}")
        return message

    def failure(self, what: str, doing: str) -> BackendError:
        self.process.join(0.5)  # let the exit code arrive
        code = self.process.exitcode
        if code is None:
            how = "its pipe closed"
        elif code < 0:
            try:
                how = f"killed by signal {-code} ({signal.Signals(-code).name})"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exit code {code}"
        hint = ""
        if doing.endswith("starting") and code == 1 and not _main_has_a_file():
            hint = ("; its error is on stderr. The main script has no file (stdin, -c or an interactive session), so "
                    "the spawned workers cannot import what it defines: put your processes and models in a module")
        elif doing.endswith("starting") and code == 1:  # the usual cause: spawn re-imports an unguarded script
            hint = ("; its error is on stderr. A script that runs the multiproc backend must start from "
                    "'if __name__ == \"__main__\":' (workers are spawned and import the main module)")
        return BackendError(f"multiproc worker {self.index} (pid {self.process.pid}) {what} {doing}: {how}; "
                            f"all workers were stopped{hint}")

    # -- ending -----------------------------------------------------------------------------
    def stop(self, graceful: bool) -> None:
        """Ask the worker to exit (``graceful``) or terminate it; kill it if it lingers."""
        process = self.process
        if graceful and process.is_alive() and self._send_error is None:
            with self._lock:
                self._queued += 1
            self._outbox.put(bytes(ForkingPickler.dumps(("stop",))))
            process.join(STOP_WAIT)
        if process.is_alive():
            process.terminate()
            process.join(KILL_WAIT)
        if process.is_alive():
            process.kill()
            process.join(KILL_WAIT)

    def release(self) -> None:
        """Close the pipe and the process handle (their file descriptors); call after ``stop``."""
        self._outbox.put(None)
        self._sender.join(KILL_WAIT)  # a send in progress fails once the worker is gone
        self.conn.close()
        if self.process.exitcode is not None:
            self.process.close()


def answers(expected: dict[int, tuple[Channel, str, str]], timeout: float, stuck=None,
            settle: bool = False) -> dict[int, tuple]:
    """Per worker, its answer (``expected``: its channel, the kind of answer and what it is doing), taken as
    they come within ``timeout`` seconds in all: a worker's error is reported at once, even while another
    waits for it (the bands of a packet wait for each other). ``stuck()``: the workers to name first
    when none answers in time (e.g. those not waiting for the others); a worker that died is named
    before one that failed because of it. ``settle``: a worker's error reply is raised only after the
    others answered (``WorkersRefused``, with how many did), so every pipe holds no stale answer: for
    messages the workers answer independently (a variable set, a parameter)."""
    replies, pending = {}, dict(expected)
    refused: list[BackendError] = []
    deadline = time.monotonic() + timeout
    while pending:
        ready = wait([h for c, _, _ in pending.values() for h in (c.conn, c.process.sentinel)],
                     max(0.0, deadline - time.monotonic()))
        # those with something to say; none within the timeout: the first one stuck
        answering = [w for w, (c, _, _) in pending.items() if c.conn in ready or c.process.sentinel in ready]
        if not answering:
            first = next(iter(pending))
            answering, ready = [next((w for w in (stuck() if stuck else ()) if w in pending), first)], None
        for worker in answering:
            channel, kind, doing = pending.pop(worker)
            try:
                replies[worker] = channel.expect(kind, max(0.0, deadline - time.monotonic()), doing, limit=timeout,
                                                 ready=ready)
            except WorkerError as err:
                if not settle:
                    _raise_if_another_died(expected, channel, doing)
                    raise
                refused.append(err)
            except BackendError:
                _raise_if_another_died(expected, channel, doing)
                raise
    if refused:
        raise WorkersRefused(refused[0], refused=len(refused), answered=len(replies))
    return replies


def _raise_if_another_died(expected: dict, channel: Channel, doing: str) -> None:
    """A worker that died is named before one that failed because of it (a band that lost its partner mid-packet
    reports that a worker went away, often before the parent sees the death): the first dead one's failure."""
    for other, _, _ in expected.values():
        if other is not channel:
            other.process.join(0.05)  # a worker whose partner saw it go is gone: let its exit code arrive
            if not other.process.is_alive():
                raise other.failure("died", f"while {doing}") from None


def _main_has_a_file() -> bool:
    """Whether the main module is a file the spawned workers can import (not stdin, -c or a REPL)."""
    import os
    path = getattr(sys.modules.get("__main__"), "__file__", None)
    return bool(path) and os.path.isfile(path)
