"""Reading throughput per format (events/s, one core) and memory while reading long files in chunks.

    python benchmarks/read_throughput.py --real FOLDER [--repeat 3] [--long 16] [--also FILE ...] [--part 1]

Part 1 reads each real sample (in ``--real``, not distributed with tofnet: AEDAT4, EVT3, DAT, EVT2) and the
EVT3 recording's 1.22 M events rewritten as AEDAT4 without frames (the DAVIS sample is
mostly APS frames, so its events/s measures frame decoding), HDF5 (DSEC layout), ROS1
bag, ``.npz`` and ``events.txt``. Each file is read whole through
``open_recording(...).chunks(1_000_000)`` (what ``read_recording`` does), pinned to one
CPU; the best of ``--repeat`` runs is printed, beside faery's bare decoding for its
formats and, for EVT3, tofnet's own decoder alone (``tofnet.io.evt3.decode_file``, no
chunks). ``--also`` reads more files the same way (e.g. a long EVT3 recording). Target:
>= 10 M events/s for AEDAT4 and EVT3.

Part 2 writes the EVT3 recording 1, 4 and ``--long`` times over (shifted in time) and
reads each in chunks of 1 M events in a fresh process: peak traced Python/numpy memory
during the read (tracemalloc, started after the imports) and peak RSS of the process
must not grow with the file's length.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CHUNK = 1_000_000


def _pin_one_core() -> str:
    if hasattr(os, "sched_setaffinity"):
        core = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {core})
        return f"pinned to CPU {core}"
    return "not pinned (no sched_setaffinity)"


def _read(path: Path) -> int:
    from tofnet.io.source import open_recording

    count = 0
    with open_recording(path) as source:
        for chunk in source.chunks(CHUNK):
            count += len(chunk)
    return count


def _faery_decode(path: Path) -> int:
    import faery

    return sum(len(packet) for packet in faery.file_decoder.Decoder(path, time_range_cache=None))


def _evt3_decode(path: Path) -> int:
    """tofnet's EVT3 decoder alone, block by block, at the header's geometry (what the reader gives it)."""
    from tofnet.io.evt3 import decode_file
    from tofnet.io.source import open_recording

    with open_recording(path) as source:
        width, height = source.sensor_size
    return sum(len(block) for block in decode_file(path, width, height))


def _is_evt3(path: Path) -> bool:
    from tofnet.io.source import open_recording

    with open_recording(path) as source:
        return source.describe() == "evt (EVT3)"


def _best(function, path: Path, repeat: int) -> tuple[float, int]:
    best, count = float("inf"), 0
    for _ in range(repeat):
        started = time.perf_counter()
        count = function(path)
        best = min(best, time.perf_counter() - started)
    return best, count


def _write_bag(path: Path, events: np.ndarray, width: int, height: int, per_message: int = 20_000) -> None:
    """A ROS1 bag of dvs_msgs/EventArray messages, serialised with numpy in the ROS1 wire layout."""
    from rosbags.rosbag1 import Writer

    from tofnet.io.rosbag import _EVENT_WIRE, typestore

    store = typestore()
    with Writer(path) as writer:
        connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
        for start in range(0, len(events), per_message):
            part = events[start:start + per_message]
            wire = np.empty(len(part), dtype=_EVENT_WIRE)
            wire["x"], wire["y"], wire["p"] = part["x"], part["y"], part["p"]
            wire["sec"], wire["nsec"] = part["t"] // 1_000_000, (part["t"] % 1_000_000) * 1000
            stamp = np.array([start, wire["sec"][0], wire["nsec"][0], 3], dtype="<u4").tobytes() + b"dvs"
            raw = stamp + np.array([height, width, len(part)], dtype="<u4").tobytes() + wire.tobytes()
            writer.write(connection, int(part["t"][0]) * 1000, raw)


def throughput(real: Path, repeat: int, scratch: Path, also: list[Path]) -> None:
    from tofnet.io import read_recording
    from tofnet.io.aedat import write_aedat4
    from tofnet.io.arrays import write_npz_recording
    from tofnet.io.events import write_events_txt
    from tofnet.io.hdf5 import write_hdf5

    print(f"Part 1: reading throughput, best of {repeat}, chunks of {CHUNK:,} events, {_pin_one_core()}")
    print(f"{'format':<22} {'file':<26} {'events':>10} {'MB':>7} {'tofnet M ev/s':>14} {'faery alone':>12} "
          f"{'tofnet EVT3 decoder':>20}")
    files = [("AEDAT4", real / "davis346.aedat4", True), ("EVT3", real / "evt3.raw", True),
             ("DAT", real / "gen4.dat", True), ("EVT2", real / "evt2.raw", True)]
    evt3 = read_recording(real / "evt3.raw")
    write_aedat4(scratch / "evt3.aedat4", [evt3.events], evt3)
    write_hdf5(scratch / "evt3.h5", [evt3.events], evt3)
    _write_bag(scratch / "evt3.bag", evt3.events, *evt3.sensor_size)
    write_npz_recording(scratch / "evt3.npz", evt3)
    write_events_txt(scratch / "events.txt", evt3.events)
    files += [("AEDAT4 (events only)", scratch / "evt3.aedat4", True), ("HDF5 (DSEC layout)", scratch / "evt3.h5", False), ("ROS1 bag", scratch / "evt3.bag", False),
              (".npz", scratch / "evt3.npz", False), ("events.txt", scratch / "events.txt", False)]
    files += [("given", path, path.suffix in (".raw", ".dat", ".aedat4", ".es")) for path in also]
    for name, path, by_faery in files:
        _read(path)  # warm up: imports, numba caches, page cache
        seconds, count = _best(_read, path, repeat)
        bare = own = ""
        if by_faery:
            bare_seconds, _ = _best(_faery_decode, path, repeat)
            bare = f"{count / bare_seconds / 1e6:.1f}"
        if _is_evt3(path):
            _evt3_decode(path)
            own_seconds, _ = _best(_evt3_decode, path, repeat)
            own = f"{count / own_seconds / 1e6:.1f}"
        size = path.stat().st_size / 1e6
        print(f"{name:<22} {path.name:<26} {count:>10,} {size:>7.1f} {count / seconds / 1e6:>14.1f} {bare:>12} "
              f"{own:>20}")


def _measure_child(path: str) -> None:
    """In a fresh process: read ``path`` in chunks; print events, tracemalloc peak and RSS peak."""
    import resource
    import tracemalloc

    from tofnet.io.source import open_recording

    with open_recording(path) as source:  # imports and compiled code loaded before measuring
        next(source.chunks(1000))
    tracemalloc.start()
    count = _read(Path(path))
    _, peak = tracemalloc.get_traced_memory()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KB
    print(count, peak / 1e6, rss)


def memory(real: Path, longest: int, scratch: Path) -> None:
    import faery

    from tofnet.io import read_recording

    events = read_recording(real / "evt3.raw").events
    span = int(events["t"][-1] - events["t"][0]) + 1
    print(f"\nPart 2: memory reading EVT3 files in chunks of {CHUNK:,} events (fresh process each)")
    print(f"{'copies':>6} {'events':>12} {'file MB':>8} {'tracemalloc peak MB':>20} {'peak RSS MB':>12}")
    for copies in sorted({1, 4, longest}):
        path = scratch / f"long_{copies}.raw"

        def stream(copies=copies):
            for k in range(copies):
                part = np.empty(len(events), dtype=faery.EVENTS_DTYPE)
                part["t"], part["x"], part["y"] = events["t"] + k * span, events["x"], events["y"]
                part["on"] = events["p"] == 1
                yield part

        faery.file_encoder.events_to_file(stream(), path, dimensions=(1280, 720), version="evt3")
        out = subprocess.run([sys.executable, __file__, "--measure", str(path)], capture_output=True, text=True,
                             check=True).stdout.split()
        count, peak, rss = int(out[0]), float(out[1]), float(out[2])
        print(f"{copies:>6} {count:>12,} {path.stat().st_size / 1e6:>8.1f} {peak:>20.1f} {rss:>12.1f}")
        path.unlink()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", type=Path, required=True, help="folder of the real samples (not distributed)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--long", type=int, default=16, help="copies of the EVT3 recording in the longest file")
    parser.add_argument("--also", type=Path, nargs="*", default=[], help="more files to read in part 1")
    parser.add_argument("--part", type=int, choices=(1, 2), help="run part 1 (throughput) or 2 (memory) only")
    parser.add_argument("--measure", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        _measure_child(args.measure)
        return
    if not args.real.is_dir():
        sys.exit(f"no real recordings at {args.real}")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        if args.part != 2:
            throughput(args.real, args.repeat, Path(scratch), args.also)
        if args.part != 1:
            memory(args.real, args.long, Path(scratch))
    print(f"\n({time.perf_counter() - started:.0f} s in all)")


if __name__ == "__main__":
    main()
