"""Memory shared by the multiproc host and its workers, that no crash can leave behind.

A buffer is an anonymous ``memfd`` (Linux): it never has a name in ``/dev/shm`` or anywhere
else, a worker maps it through ``/proc/<host pid>/fd/<fd>``, and the kernel frees it when the
last process holding it exits, however it exits (``kill -9`` of the host or of a worker
included). Imports stay light: spawned workers load this module.
"""

from __future__ import annotations

import mmap
import os

import numpy as np

from tofnet.errors import BackendError


class SharedBuffer:
    """``nbytes`` of memory the host creates and workers map (``attach``)."""

    def __init__(self, nbytes: int, name: str = "tofnet"):
        if not hasattr(os, "memfd_create"):
            raise BackendError("multiproc's shared memory needs Linux (memfd_create); use per_core=True elsewhere")
        self.nbytes = max(int(nbytes), 1)
        # the creator's pid in the name: whose buffer a mapping is (/proc/PID/maps: memfd:NAME-PID)
        self.fd = os.memfd_create(f"{name}-{os.getpid()}", os.MFD_CLOEXEC)
        try:
            os.ftruncate(self.fd, self.nbytes)
            self.map = mmap.mmap(self.fd, self.nbytes)
        except BaseException:
            os.close(self.fd)
            raise

    @property
    def address(self) -> tuple[int, int, int]:
        """What a worker needs to map it: ``(host pid, fd, bytes)``."""
        return os.getpid(), self.fd, self.nbytes

    def array(self, dtype, count: int | None = None) -> np.ndarray:
        return np.frombuffer(self.map, dtype, count if count is not None else -1)

    def close(self) -> None:
        """Unmap and close (idempotent); the memory goes once no worker maps it either."""
        if self.fd >= 0:
            try:
                self.map.close()
            except BufferError:  # a numpy view still points into it: its pages go with the process
                pass
            os.close(self.fd)
            self.fd = -1


def attach(address: tuple[int, int, int]) -> mmap.mmap:
    """A worker's mapping of the host's buffer at ``address`` (``SharedBuffer.address``)."""
    pid, fd, nbytes = address
    handle = os.open(f"/proc/{pid}/fd/{fd}", os.O_RDWR)
    try:
        return mmap.mmap(handle, nbytes)
    finally:
        os.close(handle)


class Rendezvous:
    """Pipes by which ``parties`` worker processes wait for each other (the host makes them, each worker
    opens its ends with ``Gate``, then the host closes its own: a party that dies closes its ends, so
    the others read an end of file instead of waiting for ever)."""

    def __init__(self, parties: int):
        self.pipes = [os.pipe() for _ in range(parties)]  # (read, write) per party: what the others tell it

    def address(self, party: int) -> tuple[int, int, tuple[int, ...]]:
        """What party ``party`` opens: ``(host pid, its pipe's read end, the others' write ends)``."""
        return os.getpid(), self.pipes[party][0], tuple(w for p, (_, w) in enumerate(self.pipes) if p != party)

    def close(self) -> None:
        """Close the host's ends (idempotent)."""
        for pipe in self.pipes:
            for fd in pipe:
                os.close(fd)
        self.pipes = []


class Gate:
    """A worker's ends of a ``Rendezvous``: ``gather`` waits for every party and returns what each said."""

    _WORD = np.dtype([("party", "<i8"), ("value", "<i8")])  # 16 bytes: written at once into a pipe

    def __init__(self, address: tuple[int, int, tuple[int, ...]], party: int):
        pid, read, writes = address
        self.party = party
        self.read = os.open(f"/proc/{pid}/fd/{read}", os.O_RDONLY | os.O_CLOEXEC)
        self.writes = []
        try:
            for fd in writes:
                self.writes.append(os.open(f"/proc/{pid}/fd/{fd}", os.O_WRONLY | os.O_CLOEXEC))
        except BaseException:
            self.close()
            raise

    def gather(self, value: int) -> list[int]:
        """Tell every other party ``value`` and wait for theirs: the values of all parties, in party order."""
        word = np.array([(self.party, value)], self._WORD).tobytes()
        for fd in self.writes:
            os.write(fd, word)
        values = {self.party: int(value)}
        pending = b""
        while len(values) <= len(self.writes):
            data = os.read(self.read, self._WORD.itemsize * len(self.writes))
            if not data:
                raise BackendError("another multiproc worker went away during a packet")
            pending += data
            whole = len(pending) // self._WORD.itemsize * self._WORD.itemsize
            for party, told in np.frombuffer(pending[:whole], self._WORD).tolist():
                values[party] = told
            pending = pending[whole:]
        return [values[p] for p in sorted(values)]

    def close(self) -> None:
        for fd in [self.read, *self.writes]:
            if fd >= 0:
                os.close(fd)
        self.read, self.writes = -1, []
