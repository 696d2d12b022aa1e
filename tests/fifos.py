"""Tests with FIFOs where a reader expects a file: a reader that waits on one fails the test instead
of hanging it.

A watchdog thread cannot free such a reader: h5py holds Python's lock (the GIL) while it waits in
``open()`` on a FIFO, so no other thread of the process runs. The watchdog is another process: after
``timeout`` it opens the FIFO for writing and closes it, as often as a reader opens it again (HDF5
opens a file more than once), which lets the reader go on to an end of file.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")

_RELEASE = """
import os, sys, time
time.sleep(float(sys.argv[2]))
end = time.monotonic() + 60
while time.monotonic() < end:
    try:  # succeeds only while a reader waits in open(): this process never waits for one
        os.close(os.open(sys.argv[1], os.O_WRONLY | os.O_NONBLOCK))
    except OSError:
        pass
    time.sleep(0.01)
"""


def fifo_in_place(path):
    """``path`` (a file that exists) replaced by a FIFO of the same name; returns it."""
    path.unlink()
    os.mkfifo(path)
    return path


def watched(call, fifo=None, timeout: float = 10.0) -> dict:
    """``call()``'s outcome: ``{"value": ...}`` or ``{"error": exception}``. When ``fifo`` is given, a
    reader still blocked on it after ``timeout`` s is let go and the test fails."""
    helper = subprocess.Popen([sys.executable, "-c", _RELEASE, str(fifo), str(timeout)]) if fifo else None
    started, outcome = time.monotonic(), {}
    try:
        outcome["value"] = call()
    except Exception as err:  # noqa: BLE001 - handed to the test
        outcome["error"] = err
    finally:
        if helper is not None:
            helper.kill()
            helper.wait()
    assert time.monotonic() - started < timeout, f"blocked for {timeout} s on {fifo}"
    return outcome
