"""Speed of the lava backend beside reference and fixed: wall time per 1 ms step, median of rounds.

    python benchmarks/lava_speed.py            # in the Python 3.10 venv with tofnet[lava]; ~3 min
    python benchmarks/lava_speed.py --rounds 1 --duration 0.05

Two scenes of the paper's network: the simulator's `slider` at 240x180 and the same
scene cut to a 48x36 window (the sizes of the conformance cases are smaller still).
Each backend runs the whole recording (`backend.run`) in rounds; every lava run compiles
its Lava processes and starts their runtime (forked processes), which the times include.
The first round (numba compiling, or loading its cache) is shown apart. Results: docs/lava.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import tempfile
import time
from pathlib import Path

from tofnet import depth_network
from tofnet.backends.registry import get_backend
from tofnet.errors import BackendError
from tofnet.io import read_recording
from tofnet.io.recording import Recording
from tofnet.sim.run import simulate

BACKENDS = (("reference", {}), ("fixed", {}), ("fixed", {"fuse": False}), ("lava", {}))


def window(recording: Recording, size: tuple[int, int]) -> Recording:
    """The events inside a ``size`` window at the sensor's centre, moved to its origin."""
    w, h = recording.sensor_size
    x0, y0 = (w - size[0]) // 2, (h - size[1]) // 2
    ev = recording.events
    keep = (ev["x"] >= x0) & (ev["x"] < x0 + size[0]) & (ev["y"] >= y0) & (ev["y"] < y0 + size[1])
    events = ev[keep].copy()
    events["x"] -= x0
    events["y"] -= y0
    intrinsics = dataclasses.replace(recording.intrinsics, cx=recording.intrinsics.cx - x0,
                                     cy=recording.intrinsics.cy - y0)  # the same rays at the moved pixels
    return Recording(events, sensor_size=size, intrinsics=intrinsics, trajectory=recording.trajectory,
                     source=f"{recording.source} {size[0]}x{size[1]}")


def measure(name: str, options: dict, recording: Recording, rounds: int) -> tuple[list[float], int, bytes]:
    network = depth_network(recording.sensor_size)
    times, result = [], None
    for _ in range(rounds):
        started = time.perf_counter()
        result = get_backend(name, **options).run(network, recording)
        times.append(time.perf_counter() - started)
    return times, result.steps, result.depth.tobytes()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=0.1, help="seconds of the slider scene")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="tofnet-lava-speed-")) / "slider"
    simulate("slider", folder, duration=args.duration, seed=0)
    full = read_recording(folder)
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}; {args.rounds} rounds, median")
    for recording in (window(full, (48, 36)), full):
        w, h = recording.sensor_size
        print(f"\nslider {w}x{h}, {len(recording.events):,} events, {args.duration * 1e3:.0f} ms")
        print(f"{'backend':<16} {'median s':>9} {'ms/step':>8} {'x fixed':>8}  first round")
        fixed_s, depths = None, {}
        for name, options in BACKENDS:
            label = name + ("" if not options else " fuse=False")
            try:
                times, steps, depths[label] = measure(name, options, recording, args.rounds)
            except BackendError as err:
                print(f"{label:<16} skipped: {err}")
                continue
            median = statistics.median(times)
            fixed_s = median if label == "fixed" else fixed_s
            ratio = f"{median / fixed_s:.0f}" if fixed_s else ""
            print(f"{label:<16} {median:>9.3f} {1e3 * median / steps:>8.2f} {ratio:>8}  {times[0]:.2f} s")
        if "lava" in depths:
            print(f"lava == fixed byte for byte: {depths['lava'] == depths['fixed']}")


if __name__ == "__main__":
    main()
