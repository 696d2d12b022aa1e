"""Time loading a large ECD ``events.txt`` (default 10 million lines).

Usage: ``python benchmarks/io_load.py [--lines N]``. Writes a synthetic file in the
slider_depth format to a temporary folder, then times ``read_events_txt`` on it
(the first, compiling call is timed separately from a warm one).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from tofnet.events import EVENT_DTYPE
from tofnet.io.events import read_events_txt, write_events_txt


def synthetic_events(n: int, seed: int = 0) -> np.ndarray:
    """``n`` sorted DAVIS240-sized events at about 1 M events/s."""
    rng = np.random.default_rng(seed)
    events = np.empty(n, dtype=EVENT_DTYPE)
    events["t"] = np.cumsum(rng.integers(0, 3, n))
    events["x"] = rng.integers(0, 240, n)
    events["y"] = rng.integers(0, 180, n)
    events["p"] = rng.integers(0, 2, n)
    return events


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=10_000_000)
    args = parser.parse_args()
    events = synthetic_events(args.lines)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "events.txt"
        start = time.perf_counter()
        write_events_txt(path, events)
        written = time.perf_counter() - start
        size = path.stat().st_size / 1e6
        print(f"wrote {args.lines:,} lines ({size:.0f} MB) in {written:.2f} s")
        for label in ("first load (may compile)", "second load"):
            start = time.perf_counter()
            loaded = read_events_txt(path)
            elapsed = time.perf_counter() - start
            print(f"{label}: {elapsed:.2f} s ({args.lines / elapsed / 1e6:.1f} M lines/s)")
        if not np.array_equal(loaded, events):
            raise SystemExit("round trip mismatch")
        print("round trip exact")


if __name__ == "__main__":
    main()
