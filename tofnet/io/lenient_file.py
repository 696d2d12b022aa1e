"""A file for libraries that write through Python and cannot survive a failed write (h5py)."""

from __future__ import annotations

from pathlib import Path


class LenientFile:
    """A file for a library that writes through Python (h5py's file-object driver) and
    cannot survive a failed write: libhdf5 whose close fails on a full disk stays half
    open and crashes the interpreter later (SIGSEGV). A failed write here is remembered
    (``error``), and every write after it is dropped, so the library closes cleanly; the
    caller stops early and raises ``error`` once the library is closed. Unbuffered, so
    the error is seen at the write that fails.
    """

    def __init__(self, path: str | Path):
        self.handle = open(path, "w+b", buffering=0)
        self.error: OSError | None = None

    def write(self, data) -> int:
        if self.error is None:
            try:
                view = memoryview(data)
                done = 0
                while done < len(view.cast("B")):
                    done += self.handle.write(view.cast("B")[done:])
            except OSError as err:
                self.error = err
        return len(memoryview(data).cast("B"))

    def readinto(self, buffer) -> int:
        return self.handle.readinto(buffer)

    def read(self, size: int = -1) -> bytes:
        return self.handle.read(size)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self.handle.seek(offset, whence)

    def tell(self) -> int:
        return self.handle.tell()

    def truncate(self, size: int | None = None) -> int:
        if self.error is None:
            try:
                return self.handle.truncate(size)
            except OSError as err:
                self.error = err
        return size if size is not None else self.tell()

    def flush(self) -> None:
        pass  # unbuffered

    def close(self) -> None:
        self.handle.close()

    def __enter__(self) -> "LenientFile":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
        if exc[0] is None and self.error is not None:
            raise self.error
