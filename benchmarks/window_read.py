"""How much of a large HDF5 file a time window reads (``--start/--duration``, docs/formats.md).

Usage: ``python benchmarks/window_read.py [--seconds 200] [--rate 1e6] [--folder /tmp/x]
[--text-seconds 10]``.
Writes a DSEC-layout file (``events/{t,x,y,p}``, ``t_offset``, ``ms_to_idx``; int64 t:
13 bytes per event, 2.6 GB at the defaults) in a temporary folder, then opens a 10 s
window at the start, the middle and the end, several rounds each, and reports the
bytes this process read from files (``/proc/self/io`` ``rchar``, page cache or not)
and the time, against one pass over the whole file. The folder is deleted at the end.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def rchar() -> int:
    for line in Path("/proc/self/io").read_text().splitlines():
        if line.startswith("rchar:"):
            return int(line.split()[1])
    raise RuntimeError("no rchar in /proc/self/io")


def write_file(path: Path, seconds: int, rate: float, block_s: int = 5) -> int:
    """A DSEC-layout file of ``seconds`` x ``rate`` events, written ``block_s`` seconds at a time."""
    import h5py

    rng = np.random.default_rng(0)
    per_block = int(rate * block_s)
    n = per_block * (seconds // block_s)
    with h5py.File(path, "w") as f:
        columns = {name: f.create_dataset(f"events/{name}", shape=(n,), dtype=dtype, chunks=(1 << 16,))
                   for name, dtype in (("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1"))}
        ms_to_idx = np.empty(seconds * 1000 + 1, dtype=np.uint64)
        for k in range(seconds // block_s):
            t = np.sort(rng.integers(0, block_s * 1_000_000, per_block)) + k * block_s * 1_000_000
            at = k * per_block
            columns["t"][at:at + per_block] = t
            columns["x"][at:at + per_block] = rng.integers(0, 640, per_block)
            columns["y"][at:at + per_block] = rng.integers(0, 480, per_block)
            columns["p"][at:at + per_block] = rng.integers(0, 2, per_block)
            ms = np.arange(k * block_s * 1000, (k + 1) * block_s * 1000)
            ms_to_idx[ms] = at + np.searchsorted(t, ms * 1000)
        ms_to_idx[-1] = n
        f.create_dataset("ms_to_idx", data=ms_to_idx)
        f.create_dataset("t_offset", data=np.int64(1_627_000_000_000_000))
    return n


def read_window(path: Path, start: str, duration: str) -> tuple[int, float, int]:
    """Events, seconds and bytes read to open ``path`` and read the window through its chunks."""
    from tofnet.io.source import open_recording
    from tofnet.io.window import parse_window

    before, started = rchar(), time.perf_counter()
    count = 0
    with open_recording(path, window=parse_window(start=start, duration=duration)) as source:
        for chunk in source.chunks():
            count += len(chunk)
    return count, time.perf_counter() - started, rchar() - before


def text_windows(path: Path, seconds: int, rate: float, rounds: int) -> None:
    """The same for an ``events.txt`` (parsed only in the bytes a binary search finds)."""
    from tofnet.io.events import write_events_txt
    from tofnet.io.source import open_recording

    rng = np.random.default_rng(1)
    n = int(seconds * rate)
    events = np.empty(n, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    events["t"] = np.sort(rng.integers(0, seconds * 1_000_000, n))
    events["x"], events["y"], events["p"] = rng.integers(0, 240, n), rng.integers(0, 180, n), rng.integers(0, 2, n)
    write_events_txt(path, events)
    size = path.stat().st_size
    print(f"events.txt: {n:,} lines, {seconds} s, {size / 1e6:.0f} MB")
    for where in ("0s", f"{seconds // 2}s", f"{seconds - 1}s"):
        times = []
        for _ in range(rounds):
            started = time.perf_counter()
            with open_recording(path, window=parse_window_text(where, "1s")) as source:
                count = len(source.read().events)
            times.append(time.perf_counter() - started)
        print(f"1 s window at {where:>4}: {count:,} events, median {statistics.median(times):.3f} s "
              f"(min {min(times):.3f}, max {max(times):.3f})")
    started = time.perf_counter()
    with open_recording(path) as source:
        count = len(source.read().events)
    print(f"whole file: {count:,} events in {time.perf_counter() - started:.2f} s")


def parse_window_text(start: str, duration: str):
    from tofnet.io.window import parse_window
    return parse_window(start=start, duration=duration)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=int, default=200)
    parser.add_argument("--rate", type=float, default=1e6, help="events per second")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--folder", help="where to write the file (default: a temporary folder)")
    parser.add_argument("--text-seconds", type=int, default=0,
                        help="also time 1 s windows of an events.txt this long (at --rate; 0: skip)")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="datasets-window-", dir=args.folder))
    try:
        path = folder / "events.h5"
        started = time.perf_counter()
        n = write_file(path, args.seconds, args.rate)
        size = path.stat().st_size
        print(f"file: {n:,} events, {args.seconds} s, {size / 1e9:.2f} GB, written in {time.perf_counter() - started:.1f} s")
        read_window(path, "1s", "1s")  # load the numba copy kernel once
        for where in ("0s", f"{args.seconds // 2}s", f"{args.seconds - 10}s"):
            runs = [read_window(path, where, "10s") for _ in range(args.rounds)]
            times = [r[1] for r in runs]
            print(f"10 s window at {where:>5}: {runs[0][0]:,} events, read {runs[0][2] / 1e6:.1f} MB "
                  f"({runs[0][2] / size * 100:.2f} % of the file; 10 s is {1000 / args.seconds:.2f} %), "
                  f"median {statistics.median(times):.2f} s (min {min(times):.2f}, max {max(times):.2f})")
        count, seconds, read = read_window(path, "0s", f"{args.seconds + 1}s")
        print(f"whole file:          {count:,} events, read {read / 1e6:.1f} MB in {seconds:.2f} s")
        path.unlink()
        if args.text_seconds:
            text_windows(folder / "events.txt", args.text_seconds, args.rate, args.rounds)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
