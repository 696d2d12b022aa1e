"""Watching numba compile (or load from its cache) tofnet's kernels, so runs can say so and not count it.

A first run on a fresh install compiles for 20-40 s, later runs load numba's disk cache.
One listener per process on numba's event API adds up the seconds spent compiling or
loading and counts real compiles; a ``Stopwatch`` takes the difference over a run, and
the first compile of a process is logged (logger ``tofnet.kernels``, INFO) the moment it
starts. Which numba events: docs/backends.md, "Compiling the kernels".
"""

from __future__ import annotations

import logging
import threading
import time
from contextlib import contextmanager
from typing import Callable, ContextManager, Iterator

from numba.core import event

__all__ = ["COMPILING", "Stopwatch", "announce_compiling", "compile_seconds", "kernels", "kernels_compiled"]

#: What the log says when a process starts compiling its first kernel.
COMPILING = "compiling kernels, first run only (20-60 s; numba caches them; 'tofnet warmup' does it ahead) ..."


class _Watch(event.Listener):
    """Adds up the time during which at least one thread is inside an outermost event of one kind
    (numba nests them), and counts the outermost events. Threads (a run's bands) compile or wait
    for numba's lock at the same time: their intervals are merged, not summed, so the seconds
    never exceed the wall time."""

    def __init__(self, on_first_start: Callable[[], None] | None = None):
        self.seconds, self.count = 0.0, 0
        self._depth: dict[int, int] = {}
        self._inside = 0  # threads inside an outermost event
        self._since = 0.0  # when the first of them entered
        self._guard = threading.Lock()
        self.on_start_hook = on_first_start

    def on_start(self, ev) -> None:
        me = threading.get_ident()
        with self._guard:
            self._depth[me] = self._depth.get(me, 0) + 1
            if self._depth[me] > 1:
                return
            if self._inside == 0:
                self._since = time.perf_counter()
            self._inside += 1
        if self.on_start_hook is not None:
            self.on_start_hook()

    def on_end(self, ev) -> None:
        me = threading.get_ident()
        with self._guard:
            self._depth[me] -= 1
            if self._depth[me] > 0:
                return
            self.count += 1
            self._inside -= 1
            if self._inside == 0:
                self.seconds += time.perf_counter() - self._since


_said: list[bool] = []


def announce_compiling(announced: bool = True) -> None:
    """Say (or not) ``COMPILING`` at this process's first compile: a command that says its own wait passes False."""
    if not announced and not _said:
        _said.append(True)


def _first_compile() -> None:
    if not _said:  # once per process: later compiles are part of the same wait
        _said.append(True)
        logging.getLogger("tofnet.kernels").info(COMPILING)


_LOCK = _Watch()                                  # compiles and cache loads: the time a run did not spend running
_COMPILES = _Watch(on_first_start=_first_compile)  # cache misses only: real compilation
event.register("numba:compiler_lock", _LOCK)
event.register("numba:compile", _COMPILES)


def compile_seconds() -> float:
    """Seconds this process has spent compiling kernels or loading them from numba's cache."""
    return _LOCK.seconds


def kernels_compiled() -> int:
    """Kernels this process compiled (numba cache misses), not counting those loaded from the cache."""
    return _COMPILES.count


def kernels(n: int) -> str:
    """``"1 kernel"``, ``"3 kernels"``: for the lines that report compiles."""
    return f"{n} kernel{'' if n == 1 else 's'}"


class Stopwatch:
    """Wall time since creation, split into the network's time, the time spent on kernels and the
    set-up set aside with ``aside()`` (building state, starting workers) (s)."""

    def __init__(self) -> None:
        self.started = time.perf_counter()
        self._compile0, self._count0 = _LOCK.seconds, _COMPILES.count
        #: Seconds set aside as set-up (``aside``), less the kernels' compiles within them.
        self.setup_seconds = 0.0
        #: Seconds spent reading the input between packets (``reading``): a file decoded chunk by chunk.
        self.reading_seconds = 0.0

    def setup_before(self, seconds: float) -> None:
        """``seconds`` of set-up spent before this clock started (worker processes started, say): the
        clock's span grows by them, the network's time does not."""
        self.started -= seconds
        self.setup_seconds += seconds

    def aside(self) -> ContextManager[None]:
        """Time spent inside is set-up, not the network's (a compile within it stays a compile)."""
        return self._apart("setup_seconds")

    def reading(self) -> ContextManager[None]:
        """Time spent inside is the input's (a file read between packets), not the network's."""
        return self._apart("reading_seconds")

    @contextmanager
    def _apart(self, bucket: str) -> Iterator[None]:
        """Add the seconds spent inside, less the kernels' compiles within them, to ``bucket``."""
        started, compiled = time.perf_counter(), _LOCK.seconds
        try:
            yield
        finally:
            spent = max(0.0, time.perf_counter() - started - (_LOCK.seconds - compiled))
            setattr(self, bucket, getattr(self, bucket) + spent)

    @property
    def compile_seconds(self) -> float:
        """Seconds spent compiling or loading kernels since the start."""
        return _LOCK.seconds - self._compile0

    @property
    def compiled(self) -> int:
        """Kernels compiled (cache misses) since the start."""
        return _COMPILES.count - self._count0

    def network_seconds(self) -> float:
        """Seconds since the start, less those spent on kernels, on set-up and reading (never below 0)."""
        return max(0.0, time.perf_counter() - self.started - self.compile_seconds - self.setup_seconds
                   - self.reading_seconds)
