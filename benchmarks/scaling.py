"""Several cores: workers (bands of rows) against one worker, and multiproc over shared memory, in one run.

    python benchmarks/scaling.py [--rounds 3] [--duration 0.25] [--slider 0.5] [--figure scaling.png]

Measures, each round running every configuration once on every stream (so a slow spell of a
shared machine spoils a round, not a configuration), wall time of ``run``:

- the paper's network on ``fixed`` with 2 workers against 1, on the 1280x720 ``edges`` stream at
  20 and 50 M ev/s (and at 20 M with only its events of rows 240-720: an uneven load) and on the
  simulated ``slider`` scene repeated 10 times;
- the time-surface estimator (``improved_network``) the same way;
- ``multiproc`` (2 workers, shared memory, in an open session: start-up excluded and reported
  apart) against ``fixed`` with 1;
- what 2 workers would take with a free core each (``CriticalPath``: per hand-over the slowest
  thread's CPU time, plus the serial CPU time), against 1 worker's CPU time: on a machine shared
  with other jobs the wall time cannot show it; for ``multiproc``, the host's serial CPU time (all
  but the next packet's copy, made while the workers run) plus the busiest worker's (``/proc``),
  against ``fixed`` with 1, and the host's serial CPU time itself;
- the cost of bands: CPU time of 2 bands against 1 (all threads), and per 1 ms packet at 1 M ev/s
  on 240x180, wall time of ``feed`` with 1, 2 and 4 workers (bands forced, and as chosen);
- the state each configuration holds (bytes of the kernels' arrays).

Prints the ratios (median over rounds, with their range) as a Markdown table; ``--figure``
draws speed-up against workers and per-packet latency against workers.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import streams  # noqa: E402

from tofnet.backends.bands import BandPool  # noqa: E402
from tofnet.backends.registry import get_backend  # noqa: E402
from tofnet.compiler import compile_network  # noqa: E402
from tofnet.events import EVENT_DTYPE  # noqa: E402
from tofnet.io.recording import Recording  # noqa: E402
from tofnet.networks import depth_network, improved_network  # noqa: E402


def repeated(recording: Recording, times: int) -> Recording:
    """``recording``'s events ``times`` times in a row (each copy shifted past the previous one)."""
    ev = recording.events
    span = int(ev["t"][-1] - ev["t"][0]) + 1000
    parts = []
    for k in range(times):
        part = ev.copy()
        part["t"] += k * span
        parts.append(part)
    out = np.concatenate(parts).astype(EVENT_DTYPE)
    return Recording(out, intrinsics=recording.intrinsics, trajectory=None, sensor_size=recording.sensor_size)


def timed(fn) -> tuple[float, float]:
    """(wall s, CPU s of the whole process) of ``fn()``."""
    cpu, wall = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


class CriticalPath:
    """While active, times every job the bands' thread pools run (CPU time of its thread): per hand-over
    the slowest thread's share, summed, is what the run would take in its threads on free cores; the
    rest of the process's CPU time is the serial part. Load does not distort CPU time much, so this
    says what a quiet machine would show when the wall time of a shared one cannot."""

    def __init__(self):
        self.parallel = self.jobs = 0.0
        self._run = BandPool.run

    def __enter__(self):
        path, run = self, self._run

        def timed_run(pool, job, jobs, serial=False):
            shares = {}

            def timed(b):
                start = time.thread_time()
                try:
                    return job(b)
                finally:
                    key = threading.get_ident()
                    shares[key] = shares.get(key, 0.0) + time.thread_time() - start
            out = run(pool, timed, jobs, serial)
            path.parallel += max(shares.values(), default=0.0)
            path.jobs += sum(shares.values())
            return out
        BandPool.run = timed_run
        return self

    def __exit__(self, *exc):
        BandPool.run = self._run


def free_cores(fn) -> tuple[float, float, float]:
    """(wall s, CPU s, estimated wall s on free cores: serial CPU + the slowest thread per hand-over) of ``fn()``."""
    with CriticalPath() as path:
        wall, cpu = timed(fn)
    return wall, cpu, cpu - path.jobs + path.parallel


def process_cpu(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` has used so far (``/proc``, clock ticks)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def free_cores_multiproc(session, fn) -> tuple[float, float, float]:
    """(wall s, estimated wall s on free cores, the host's serial CPU s) of ``fn()`` on ``session``'s
    workers: the host's CPU time outside what it does while the workers run (``_exchange``'s
    ``meanwhile``: copying the next packet) plus the busiest worker's (the host waits for the workers
    and the workers for the host the rest of the time)."""
    exchange, overlapped = session._exchange, [0.0]

    def timed_exchange(messages, stuck=None, meanwhile=None):
        def measured():
            start = time.thread_time()
            meanwhile()
            overlapped[0] += time.thread_time() - start
        return exchange(messages, stuck, measured if meanwhile is not None else None)

    before = [process_cpu(pid) for pid in session.pids]
    session._exchange = timed_exchange
    try:
        wall, host = timed(fn)
    finally:
        del session._exchange
    busiest = max(process_cpu(pid) - b for pid, b in zip(session.pids, before))
    return wall, host - overlapped[0] + busiest, host - overlapped[0]


def networks(sensor, recording: Recording) -> dict:
    velocity = {"source": "constant", "velocity": list(streams.SYNTHETIC_VELOCITY)}
    if recording.trajectory is not None:
        velocity = {"source": "groundtruth"}
    return {"paper": depth_network(sensor, velocity=velocity),
            "time surface": improved_network(sensor, velocity=velocity)}


def state_bytes(stream) -> int:
    kernel = stream.kernel
    kernels = getattr(kernel, "kernels", [kernel])
    return sum(k._ints.nbytes + k._floats.nbytes for k in kernels)


def packet_latency(workers: int, force: bool, rounds: int) -> float:
    """Median wall µs of ``feed`` for 1 ms packets at 1 M ev/s on 240x180 (bands forced or as chosen)."""
    recording = streams.edges((240, 180), 1e6, 0.3)
    network = depth_network((240, 180), velocity={"source": "constant", "velocity": list(streams.SYNTHETIC_VELOCITY)})
    ev = recording.events
    steps = (ev["t"] - ev["t"][0]) // 1000
    parts = np.split(ev, np.flatnonzero(np.diff(steps)) + 1)
    best = []
    for _ in range(rounds):
        stream = get_backend("fixed", workers=workers).open_stream(network, recording=recording)
        if force and hasattr(stream.kernel, "one_band_below"):
            stream.kernel.one_band_below = 0
        times = []
        for part in parts:
            start = time.perf_counter()
            stream.feed(part)
            times.append(time.perf_counter() - start)
        stream.close()
        best.append(np.median(times[20:]) * 1e6)
    return float(np.median(best))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=0.25, help="seconds of each edges stream")
    parser.add_argument("--slider", type=float, default=0.5, help="seconds of the slider scene (repeated 10x)")
    parser.add_argument("--figure", help="write the figure here (PNG)")
    parser.add_argument("--figure-only", action="store_true", help="only the figure's measurements")
    parser.add_argument("--networks", default="paper,time surface",
                        help="which networks' rows (comma-separated; the latency and state tables need 'paper')")
    args = parser.parse_args()
    print(f"# {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the start", flush=True)
    sensor = (1280, 720)
    inputs = {"edges 1280x720 20M": streams.edges(sensor, 20e6, args.duration),
              "edges 1280x720 50M": streams.edges(sensor, 50e6, args.duration)}
    edges = inputs["edges 1280x720 20M"]  # its events in the lower two thirds only: where balance by load matters
    inputs["edges 20M, rows 240-720"] = Recording(edges.events[edges.events["y"] >= 240], intrinsics=edges.intrinsics,
                                                  trajectory=edges.trajectory, sensor_size=sensor)
    slider = streams.scenario("slider", args.slider, print)
    inputs["slider x10"] = repeated(slider, 10)
    configs = {"1": lambda: get_backend("fixed"), "2": lambda: get_backend("fixed", workers=2)}
    if args.figure_only:
        return figure(args, inputs["edges 1280x720 20M"], {w: (packet_latency(w, False, args.rounds),
                                                               packet_latency(w, True, args.rounds)) for w in (1, 2, 4)})
    ratios: dict[tuple[str, str], list[float]] = {}
    cpu_ratio: dict[tuple[str, str], list[float]] = {}
    free_ratio: dict[tuple[str, str], list[float]] = {}
    mp_ratio: dict[str, list[float]] = {}
    mp_free: dict[str, list[float]] = {}
    mp_serial: dict[str, list[float]] = {}  # the multiproc host's serial CPU ms
    with get_backend("multiproc", workers=2).session() as session:
        startup = session.startup_seconds
        for recording in inputs.values():  # compile (or load) every kernel before timing anything
            head = Recording(recording.events[:200_000], intrinsics=recording.intrinsics,
                             trajectory=recording.trajectory, sensor_size=recording.sensor_size)
            for kind, network in networks(recording.sensor_size, recording).items():
                if kind not in args.networks.split(","):
                    continue
                for make in configs.values():
                    make().run(network, head)
                if kind == "paper":
                    session.run(head, compiled=compile_network(network))
        for r in range(args.rounds):
            for name, recording in inputs.items():
                for kind, network in networks(recording.sensor_size, recording).items():
                    if kind not in args.networks.split(","):
                        continue
                    compiled = compile_network(network)
                    one, cpu_one = timed(lambda: configs["1"]().run(compiled, recording))
                    two, cpu_two, free_two = free_cores(lambda: configs["2"]().run(compiled, recording))
                    ratios.setdefault((name, kind), []).append(one / two)
                    cpu_ratio.setdefault((name, kind), []).append(cpu_two / cpu_one)
                    free_ratio.setdefault((name, kind), []).append(cpu_one / free_two)
                    if kind == "paper":
                        mp, mp_cpu, serial = free_cores_multiproc(
                            session, lambda: session.run(recording, compiled=compiled))
                        mp_ratio.setdefault(name, []).append(one / mp)
                        mp_free.setdefault(name, []).append(cpu_one / mp_cpu)
                        mp_serial.setdefault(name, []).append(serial * 1e3)
                    print(f"round {r} {name} {kind}: 1 worker {one:.2f} s, 2 workers {two:.2f} s", flush=True)
    print(f"\n# load average {os.getloadavg()[0]:.1f} at the end; multiproc start-up {startup:.2f} s (excluded)\n")

    def fmt(values):
        return f"{statistics.median(values):.2f}x ({min(values):.2f}-{max(values):.2f})"

    def ms(values):
        return f"{statistics.median(values):.0f} ({min(values):.0f}-{max(values):.0f})"

    print("| stream | network | 2 workers vs 1 (wall) | on free cores (CPU) | CPU time 2 vs 1 | multiproc 2 vs fixed 1 "
          "(wall) | multiproc on free cores (CPU) | multiproc host's serial CPU ms |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for (name, kind), values in ratios.items():
        mp = f"{fmt(mp_ratio[name])} | {fmt(mp_free[name])} | {ms(mp_serial[name])}" if kind == "paper" else "- | - | -"
        print(f"| {name} | {kind} | {fmt(values)} | {fmt(free_ratio[(name, kind)])} | {fmt(cpu_ratio[(name, kind)])} "
              f"| {mp} |")

    if "paper" not in args.networks.split(","):
        return
    print("\n| workers | 1 ms packet, bands as chosen (µs, median) | bands forced (µs) |")
    print("| --- | --- | --- |")
    latency = {}
    for w in (1, 2, 4):
        latency[w] = (packet_latency(w, False, args.rounds), packet_latency(w, True, args.rounds))
        print(f"| {w} | {latency[w][0]:.1f} | {latency[w][1]:.1f} |", flush=True)

    recording = inputs["edges 1280x720 20M"]
    network = networks(sensor, recording)["paper"]
    print("\n| workers | kernel state MB |")
    print("| --- | --- |")
    for w in (1, 2, 4):
        stream = get_backend("fixed", workers=w).open_stream(network, recording=recording)
        if hasattr(stream.kernel, "one_band_below"):
            stream.kernel.one_band_below = 0
        stream.feed(recording.events[:1 << 17])
        print(f"| {w} | {state_bytes(stream) / 1e6:.1f} |")
        stream.close()

    if args.figure:
        figure(args, recording, latency)


def figure(args, recording: Recording, latency: dict) -> None:
    """Speed-up against workers (wall, and what CPU time says each would reach on a free core) and
    per-packet latency against workers."""
    network = networks(recording.sensor_size, recording)["paper"]
    compiled = compile_network(network)
    get_backend("fixed", workers=2).run(compiled, recording)  # warm
    walls, cpus = {w: [] for w in (1, 2, 3, 4)}, {w: [] for w in (1, 2, 3, 4)}
    for _ in range(args.rounds):
        for w in walls:
            wall, cpu = timed(lambda: get_backend("fixed", workers=w).run(compiled, recording))
            walls[w].append(wall)
            cpus[w].append(cpu)
    wall = {w: float(np.median(v)) for w, v in walls.items()}
    cpu = {w: float(np.median(v)) for w, v in cpus.items()}
    speedups = {w: wall[1] / wall[w] for w in wall}
    bound = {w: w * cpu[1] / cpu[w] for w in cpu}  # N threads each on a free core, at the CPU time measured
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.4))
    a.plot(list(speedups), list(speedups.values()), "o-", label="measured wall time (this machine)")
    a.plot(list(bound), list(bound.values()), "s--", label="N x CPU(1) / CPU(N): a free core per thread")
    a.plot([1, 4], [1, 4], ":", color="grey", label="ideal")
    a.set(xlabel="workers", ylabel="speed-up vs 1 worker", title="paper network, edges 1280x720 20M")
    a.legend(fontsize=8)
    ws = list(latency)
    b.plot(ws, [latency[w][0] for w in ws], "o-", label="bands as chosen")
    b.plot(ws, [latency[w][1] for w in ws], "s--", label="bands forced")
    b.set(xlabel="workers", ylabel="µs per 1 ms packet (median)", title="240x180, 1 M ev/s, 1 ms packets")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.figure, dpi=110)
    print(f"\nfigure: {args.figure}; speed-ups {', '.join(f'{w}: {s:.2f}x' for w, s in speedups.items())}; "
          f"CPU-time bound {', '.join(f'{w}: {s:.2f}x' for w, s in bound.items())}")


if __name__ == "__main__":
    main()
