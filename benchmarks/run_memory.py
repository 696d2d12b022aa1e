"""Memory of ``tofnet run`` on long files: the events stream through the network in chunks.

    python benchmarks/run_memory.py            # 1, 4 and 16 M events (about 2 minutes; needs the hdf5 extra)
    python benchmarks/run_memory.py --quick    # 0.5 and 2 M events

Writes DSEC-layout HDF5 files of a moving texture (benchmarks/streams.py ``edges``, 1 M
events/s, 240x180) chunk by chunk, then runs the paper's network on each through
``tofnet.api.run_source`` (what ``tofnet run`` does for a file that states its sensor
size) and prints the tracemalloc peak of the run beside the size the events would take in
memory. The peak grows with the estimates kept (28 B each, about a sixth of the events
here) until they pass 256 MB and go to a temporary file; it does not grow with the events.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import streams
from tofnet.events import EVENT_DTYPE
from tofnet.io.hdf5 import write_hdf5
from tofnet.io.recording import Intrinsics, Recording
from tofnet.io.source import open_recording
from tofnet.networks import depth_network

INTRINSICS = Intrinsics(199.1, 198.5, 119.5, 89.5)
VELOCITY = (-0.5, 0.05, 0.1)


def write_file(path: Path, millions: float) -> int:
    """An HDF5 file of about ``millions`` M events, made one second at a time."""
    seconds = max(1, int(round(millions)))

    def chunks():
        for s in range(seconds):
            events = streams.edges((240, 180), millions * 1e6 / seconds, 1.0, seed=s).events
            events["t"] += s * 1_000_000
            yield events
    meta = Recording(np.empty(0, EVENT_DTYPE), intrinsics=INTRINSICS, sensor_size=(240, 180))
    return write_hdf5(path, chunks(), meta)


def peak_of_run(path: Path) -> tuple[float, int, float]:
    """tracemalloc peak (MB), estimates and seconds of running the paper network on ``path``."""
    from tofnet.api import run_source
    net = depth_network((240, 180), velocity={"source": "constant", "velocity": list(VELOCITY)})
    with open_recording(path) as source:
        tracemalloc.start()
        started = time.perf_counter()
        result, _ = run_source(source, net, spill_dir=path.parent)
        seconds = time.perf_counter() - started
        peak = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
    return peak, len(result.depth), seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    sizes = (0.5, 2.0) if parser.parse_args().quick else (1.0, 4.0, 16.0)
    print("| events | events in memory would take | run's peak (tracemalloc) | estimates | run s |")
    print("| --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as folder:
        for millions in sizes:
            path = Path(folder) / f"edges_{millions:g}M.h5"
            n = write_file(path, millions)
            peak, estimates, seconds = peak_of_run(path)
            print(f"| {n:,} | {n * EVENT_DTYPE.itemsize / 1e6:.0f} MB | {peak:.0f} MB | {estimates:,} | {seconds:.1f} |",
                  flush=True)
            path.unlink()


if __name__ == "__main__":
    main()
