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
