"""Speed of the event-driven backends: one table, the targets, and the reference and the chip beside them.

    python benchmarks/performance.py            # about 10 minutes (+1 min to simulate the scenes once)
    python benchmarks/performance.py --quick    # under a minute: fewer streams, 0.3 s long, 2 rounds

Run by hand (not in CI), on an idle machine if possible: it prints the load average
and a timing noise floor (the p50/p99 of a fixed 30 µs computation). Everything runs
on one core except the multiproc section. Results: docs/performance.md.

Streams (benchmarks/streams.py): the simulator's built-in scenes at 240x180 (simulated
once, cached), and synthetic streams of 0.1-20 M events/s of two kinds, ``uniform``
(random pixels, the worst case for caches) and ``edges`` (a moving texture with
bursts and 10 % noise, with a real scene's locality). Each is measured in rounds
(every stream once per round, best round kept), so that a slow spell of a shared
machine spoils one round rather than one stream:

- throughput: ``backend.run`` on the whole stream (CPU time), events/s; for ``fixed`` also
  with ``fuse=False``: the paper's network run model by model, as any other graph runs; and
  the time-surface estimator (``improved_network``, beyond the paper) on the ``fixed`` backend;
- µs per 1 ms timestep, bulk: the stream fed to an open stream in ``run``'s packets
  (no set-up), CPU time / the stream's steps;
- streaming: one packet per 1 ms timestep (``open_stream``, ``feed``); mean µs per
  packet, and latency p50/p99 = wall time from ``feed(packet)`` to its return with the
  packet's depth estimates;
- memory: tracemalloc peak while streaming a tenth of the stream and all of it (state
  + per-packet buffers: it must not grow with the stream's length);
- the step-by-step ``reference`` backend on the stream's first 0.1 s (it is slow),
  compared per step and per event.

Then resolution scaling at equal event rate (with the default refractory period and
with none, which gives every sensor size the same work per event), the multiproc
backend's speed-up and start-up, and the targets with PASS/FAIL. Several cores (``--workers``,
``multiproc``'s bands against ``fixed`` with one worker, with their costs, memory and the
per-packet latency) are measured by ``benchmarks/scaling.py``, and what two threads of the
machine can give at best by ``benchmarks/machine_ceiling.py``.
"""

from __future__ import annotations

import argparse
import gc
import os
import platform
import subprocess
import time
import tracemalloc

import numpy as np

import streams
from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.backends.stream import DEFAULT_PACKET_EVENTS
from tofnet.backends.reference import ReferenceBackend
from tofnet.io.recording import Recording
from tofnet.networks import depth_network, improved_network
from tofnet.processes.input import DEFAULT_REFRACTORY

CHIP_US_PER_STEP = 400.0  # Loihi 2 at 240x180 (paper); ~100 µs at half resolution
CPU_METHODS_EV_S = (1.0e6, 1.2e6)  # the CPU methods the paper cites
SCENES = ("slider", "fast_slider", "vertical", "diagonal", "all_axes", "forward")
RATES = (0.1e6, 1e6, 5e6, 10e6, 20e6)
SENSORS = ((240, 180), (346, 260), (640, 480), (1280, 720))
TARGETS = {"throughput": 20e6, "us_per_step": 40.0, "p99_us": 100.0, "resolution_ratio": 1.5, "unfused_ratio": 3.0,
           "time_surface": 10e6}


def say(text: str) -> None:
    print(text, flush=True)


def machine() -> str:
    model = next((line.split(":", 1)[1].strip() for line in subprocess.run(
        ["lscpu"], capture_output=True, text=True).stdout.splitlines() if line.startswith("Model name")), "?")
    return f"{model}, {os.cpu_count()} CPUs, Python {platform.python_version()}"


def load() -> str:
    return "load average " + " ".join(f"{v:.2f}" for v in os.getloadavg())


def noise_floor(target_us: float = 30.0, count: int = 3000) -> tuple[float, float]:
    """p50 and p99 wall time (µs) of a fixed ~``target_us`` computation: the machine's own timing noise.

    A 1 ms packet's latency cannot have a tail below this one's (interrupts, other jobs)."""
    from numba import njit

    @njit(cache=False)
    def spin(n):
        total = 0
        for i in range(n):
            total += i * i % 7
        return total

    spin(10)
    n = 1000
    while True:  # calibrate n so that one call takes about target_us
        started = time.perf_counter()
        spin(n)
        if time.perf_counter() - started > target_us * 1e-6 or n > 1 << 30:
            break
        n *= 2
    seconds = np.empty(count)
    for i in range(count):
        started = time.perf_counter()
        spin(n)
        seconds[i] = time.perf_counter() - started
    return np.percentile(seconds, 50) * 1e6, np.percentile(seconds, 99) * 1e6


def network(sensor, refractory: str):
    return depth_network(sensor, input={"refractory": refractory})


def cpu_once(fn) -> float:
    """CPU seconds of one call (CPU, not wall time: the neighbours' load matters less)."""
    gc.collect()
    started = time.process_time()
    fn()
    return time.process_time() - started


def steps_of(recording: Recording) -> int:
    t = recording.events["t"]
    return int((int(t[-1]) - int(t[0])) // 1000 + 1)


def packets(recording: Recording) -> list[np.ndarray]:
    """The stream cut into one packet per 1 ms timestep (t0 = the first event)."""
    t = recording.events["t"]
    bounds = np.searchsorted(t, np.arange(int(t[0]), int(t[-1]) + 1001, 1000))
    return [recording.events[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]


def open_stream(net, recording: Recording):
    return FixedBackend().open_stream(net, intrinsics=recording.intrinsics, velocity_source=recording.trajectory,
                                      t0_us=int(recording.events["t"][0]))


def bulk_once(net, recording: Recording) -> float:
    """CPU seconds to feed the stream into an open stream in ``run``'s packets (no set-up, unlike ``run``)."""
    stream, events = open_stream(net, recording), recording.events
    return cpu_once(lambda: [stream.feed(events[lo:lo + DEFAULT_PACKET_EVENTS])
                             for lo in range(0, len(events), DEFAULT_PACKET_EVENTS)])


def stream_once(net, recording: Recording, parts: list[np.ndarray]) -> np.ndarray:
    """Feed ``parts`` one by one; wall time of each ``feed`` (s)."""
    stream = open_stream(net, recording)
    seconds = np.empty(len(parts))
    clock = time.perf_counter
    for i, part in enumerate(parts):
        started = clock()
        stream.feed(part)
        seconds[i] = clock() - started
    return seconds


class Job:
    """One stream on one network, measured in rounds (each round once per kind of measurement)
    so that a slow spell of the shared machine hits one round, not all of a stream's repeats."""

    def __init__(self, name: str, recording: Recording, refractory: str, backends=True):
        self.name, self.recording, self.backends = name, recording, backends
        self.net = network(recording.sensor_size, refractory)
        self.improved = improved_network(recording.sensor_size)  # the time-surface estimator
        self.parts = packets(recording)
        self.rounds: list[dict] = []

    def round(self) -> None:
        net, recording = self.net, self.recording
        if not self.rounds:  # compile and warm up
            stream_once(net, recording, self.parts[:50])
            FixedBackend().run(net, recording), FloatBackend().run(net, recording)
            if self.backends:
                FixedBackend(fuse=False).run(net, recording)
                FixedBackend().run(self.improved, recording)
        measured = {"bulk": bulk_once(net, recording), "packets": stream_once(net, recording, self.parts)}
        if self.backends:
            measured["fixed"] = cpu_once(lambda: FixedBackend().run(net, recording))
            measured["float"] = cpu_once(lambda: FloatBackend().run(net, recording))
            # the same network model by model (no fusion): what any other graph runs like
            measured["unfused"] = cpu_once(lambda: FixedBackend(fuse=False).run(net, recording))
            measured["improved"] = cpu_once(lambda: FixedBackend().run(self.improved, recording))
        self.rounds.append(measured)

    def best(self) -> dict:
        """Least CPU time of each kind, and the pass of 1 ms packets with the least mean."""
        best = {k: min(r[k] for r in self.rounds) for k in self.rounds[0] if k != "packets"}
        packets_s = min((r["packets"] for r in self.rounds), key=np.mean)
        n, steps = len(self.recording.events), steps_of(self.recording)
        best.update(n=n, steps=steps, accepted=FixedBackend().run(self.net, self.recording).accepted,
                    bulk_us_step=best["bulk"] / steps * 1e6, stream_mean=packets_s.mean() * 1e6,
                    stream_p50=np.percentile(packets_s, 50) * 1e6, stream_p99=np.percentile(packets_s, 99) * 1e6)
        return best


def run_rounds(jobs: list[Job], repeat: int) -> None:
    for r in range(repeat):
        for i, job in enumerate(jobs):
            say(f"  round {r + 1}/{repeat}, {i + 1}/{len(jobs)}: {job.name}")
            job.round()


def peak_memory(net, recording: Recording) -> tuple[float, float]:
    """tracemalloc peak (MB) while streaming the first tenth of the packets, and all of them."""
    parts = packets(recording)
    peaks = []
    for count in (max(len(parts) // 10, 1), len(parts)):
        tracemalloc.start()
        stream_once(net, recording, parts[:count])
        peaks.append(tracemalloc.get_traced_memory()[1] / 1e6)
        tracemalloc.stop()
    return peaks[0], peaks[1]


def reference_slice(net, recording: Recording, seconds: float = 0.1) -> dict:
    """The reference backend on the first ``seconds`` of the stream: CPU s per step and per event."""
    t = recording.events["t"]
    events = recording.events[:int(np.searchsorted(t, int(t[0]) + seconds * 1e6))]
    piece = Recording(events, intrinsics=recording.intrinsics, trajectory=recording.trajectory,
                      sensor_size=recording.sensor_size)
    cpu = cpu_once(lambda: ReferenceBackend().run(net, piece))
    return {"us_per_step": cpu / steps_of(piece) * 1e6, "ns_per_event": cpu / max(len(events), 1) * 1e9}


def row_of(job: Job, memory: bool) -> dict:
    b = job.best()
    n = b["n"]
    row = {"stream": job.name, "rate": n / (b["steps"] * 1e-3), "accepted": b["accepted"] / max(n, 1),
           "fixed_ev_s": n / b["fixed"], "float_ev_s": n / b["float"], "unfused_ev_s": n / b["unfused"],
           "improved_ev_s": n / b["improved"],
           "steady_us_step": b["bulk_us_step"],
           **{k: b[k] for k in ("stream_mean", "stream_p50", "stream_p99")}}
    if memory:
        row["mem_tenth"], row["mem_all"] = peak_memory(job.net, job.recording)
    reference = reference_slice(job.net, job.recording)
    row["ref_us_step"] = reference["us_per_step"]
    row["ref_speedup"] = reference["ns_per_event"] / (b["fixed"] / n * 1e9)
    return row


def main_table(rows: list[dict]) -> str:
    head = ("| stream | M ev/s in | accepted | fixed M ev/s | float M ev/s | fixed unfused M ev/s (x slower) "
            "| time surface M ev/s "
            "| µs/step (bulk) | µs/step (1 ms packets) "
            "| p50 / p99 µs | peak MB (0.1x / 1x stream) | reference µs/step | fixed vs reference "
            "| vs chip 400 µs/step |")
    lines = [head, "|" + "|".join(" --- " for _ in range(head.count("|") - 1)) + "|"]
    for r in rows:
        mem = f"{r['mem_tenth']:.1f} / {r['mem_all']:.1f}" if "mem_all" in r else "-"
        lines.append(
            f"| {r['stream']} | {r['rate'] / 1e6:.2f} | {r['accepted']:.0%} | {r['fixed_ev_s'] / 1e6:.1f} "
            f"| {r['float_ev_s'] / 1e6:.1f} | {r['unfused_ev_s'] / 1e6:.1f} ({r['fixed_ev_s'] / r['unfused_ev_s']:.1f}x) "
            f"| {r['improved_ev_s'] / 1e6:.1f} "
            f"| {r['steady_us_step']:.1f} | {r['stream_mean']:.1f} "
            f"| {r['stream_p50']:.0f} / {r['stream_p99']:.0f} | {mem} | {r['ref_us_step']:.0f} "
            f"| {r['ref_speedup']:.0f}x | {CHIP_US_PER_STEP / r['stream_mean']:.1f}x faster |")
    return "\n".join(lines)


def scaling_jobs(kind: str, rate: float, duration: float, refractory: str) -> list[Job]:
    """The same event rate on every sensor size."""
    return [Job(f"{kind} {w}x{h} refractory {refractory}", getattr(streams, kind)((w, h), rate, duration), refractory,
                backends=False) for w, h in SENSORS]


def scaling_rows(jobs: list[Job]) -> list[dict]:
    """µs per 1 ms step (bulk, and 1 ms packets), events accepted, and the set-up of a stream."""
    rows = []
    for job in jobs:
        b = job.best()
        setup = min(cpu_once(lambda: open_stream(job.net, job.recording)) for _ in range(3))
        rows.append({"us_step": b["bulk_us_step"], "accepted": b["accepted"] / b["n"],
                     "ns_accepted": b["bulk"] / max(b["accepted"], 1) * 1e9, "stream_mean": b["stream_mean"],
                     "setup_ms": setup * 1e3})
    return rows


def scaling_table(results: dict[str, list[dict]]) -> str:
    lines = ["| stream | sensor | set-up ms | µs/step (bulk) | vs 240x180 | µs/step (1 ms packets) | accepted "
             "| ns per accepted event |", "|" + "|".join(" --- " for _ in range(8)) + "|"]
    for name, rows in results.items():
        for sensor, r in zip(SENSORS, rows):
            lines.append(f"| {name} | {sensor[0]}x{sensor[1]} | {r['setup_ms']:.1f} | {r['us_step']:.1f} "
                         f"| {r['us_step'] / rows[0]['us_step']:.2f}x | {r['stream_mean']:.1f} | {r['accepted']:.0%} "
                         f"| {r['ns_accepted']:.0f} |")
    return "\n".join(lines)


def multiproc(recording: Recording, refractory: str) -> list[str]:
    """Wall time of fixed vs multiproc (1 and 2 workers; the paper's 30x30 mapping) and the workers' start-up."""
    from tofnet.backends.multiproc import MultiprocBackend
    from tofnet.compiler import compile_network

    compiled = compile_network(network(recording.sensor_size, refractory), patch=(30, 30))
    FixedBackend().run(compiled, recording)
    fixed = min(FixedBackend().run(compiled, recording).wall_time for _ in range(3))
    lines = ["| backend | start-up s | run s (wall) | speed-up vs fixed | vs 1 worker |",
             "| --- | --- | --- | --- | --- |", f"| fixed | 0 | {fixed:.3f} | 1.00x | |"]
    one = None
    for workers in (1, 2):
        with MultiprocBackend(workers=workers).session(compiled) as session:
            session.run(recording)
            run = min(session.run(recording).wall_time for _ in range(2))
        one = one or run
        lines.append(f"| multiproc, {workers} worker{'s' if workers > 1 else ''} | {session.startup_seconds:.2f} "
                     f"| {run:.3f} | {fixed / run:.2f}x | {one / run:.2f}x |")
        say(f"  multiproc {workers}: start-up {session.startup_seconds:.2f} s, run {run:.3f} s")
    return lines


def verdict(name: str, target: str, value: float, ok: bool, why: str = "") -> str:
    return f"| {name} | {target} | {value} | {'PASS' if ok else 'FAIL'} | {why} |"


def targets(rows: list[dict], scale: dict[str, list[dict]]) -> str:
    bulk = [r for r in rows if not r["stream"].startswith(("uniform 0.1", "edges 0.1"))]
    slowest = min(bulk, key=lambda r: r["fixed_ev_s"])
    at_1m = [r for r in rows if r["stream"] in ("uniform 1M", "edges 1M")]
    worst_step = max(at_1m, key=lambda r: r["stream_mean"])
    worst_p99 = max(at_1m, key=lambda r: r["stream_p99"])
    ratios = {k: v[-1]["us_step"] / v[0]["us_step"] for k, v in scale.items()}
    lines = ["| target (one core) | goal | measured | | where |", "| --- | --- | --- | --- | --- |",
             verdict("fixed backend throughput", ">= 20 M ev/s", f"{slowest['fixed_ev_s'] / 1e6:.1f} M ev/s",
                     slowest["fixed_ev_s"] >= TARGETS["throughput"], f"slowest stream: {slowest['stream']}"),
             verdict("µs per 1 ms step, 240x180, 1 M ev/s (1 ms packets)", "<= 40 µs",
                     f"{worst_step['stream_mean']:.1f} µs", worst_step["stream_mean"] <= TARGETS["us_per_step"],
                     worst_step["stream"]),
             verdict("p99 latency, 1 ms packets, 1 M ev/s", "<= 100 µs", f"{worst_p99['stream_p99']:.0f} µs",
                     worst_p99["stream_p99"] <= TARGETS["p99_us"], worst_p99["stream"])]
    for kind, ratio in ratios.items():
        lines.append(verdict(f"1280x720 vs 240x180 at 1 M ev/s, {kind}", "<= 1.5x", f"{ratio:.2f}x",
                             ratio <= TARGETS["resolution_ratio"], "µs per step, bulk, without set-up"))
    worst = max(bulk, key=lambda r: r["fixed_ev_s"] / r["unfused_ev_s"])
    slowdown = worst["fixed_ev_s"] / worst["unfused_ev_s"]
    lines.append(verdict("the paper's network model by model (unfused) vs fused", "<= 3x slower", f"{slowdown:.1f}x",
                         slowdown <= TARGETS["unfused_ratio"], f"worst stream: {worst['stream']}"))
    fixed_rate = [r for r in bulk if r["stream"].startswith(("uniform", "edges"))] or bulk
    slow = min(fixed_rate, key=lambda r: r["improved_ev_s"])
    passing = [r["stream"] for r in fixed_rate if r["improved_ev_s"] >= TARGETS["time_surface"]]
    lines.append(verdict("time-surface estimator throughput (fixed-rate streams)", ">= 10 M ev/s",
                         f"{slow['improved_ev_s'] / 1e6:.1f} M ev/s", slow["improved_ev_s"] >= TARGETS["time_surface"],
                         f"slowest: {slow['stream']}; at or above 10 M: {', '.join(passing) or 'none'}"))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="about 1 minute: fewer streams, shorter, fewer repeats")
    parser.add_argument("--refractory", default=DEFAULT_REFRACTORY, help=f"default {DEFAULT_REFRACTORY}")
    parser.add_argument("--no-multiproc", action="store_true")
    args = parser.parse_args()
    quick = args.quick
    duration, repeat = (0.3, 2) if quick else (1.0, 3)
    say(f"tofnet speed: {machine()}; {load()}")
    floor = noise_floor()
    say(f"timing noise floor: a fixed ~30 µs computation takes p50 {floor[0]:.1f} µs, p99 {floor[1]:.1f} µs here")
    say(f"refractory {args.refractory}, 1 ms steps, fixed-point backend unless stated; "
        f"{'quick' if quick else 'full'} run ({duration:g} s streams, best of {repeat} rounds)")
    say("streams ...")
    jobs = [Job(name, streams.scenario(name, duration, say), args.refractory)
            for name in (SCENES[:2] if quick else SCENES)]
    jobs += [Job(f"{kind} {rate / 1e6:g}M", getattr(streams, kind)((240, 180), rate, duration), args.refractory)
             for kind in ("uniform", "edges") for rate in ((1e6, 20e6) if quick else RATES)]
    run_rounds(jobs, repeat)
    say("memory and the reference backend ...")
    rows = [row_of(job, memory=not quick or job.name == "edges 1M") for job in jobs]
    say("resolution scaling at 1 M events/s ...")
    refractories = (args.refractory,) if quick else (args.refractory, "0")  # 0: the same work per event everywhere
    scale_jobs = {f"{kind}, refractory {r}": scaling_jobs(kind, 1e6, duration, r)
                  for r in refractories for kind in ("uniform", "edges")}
    run_rounds([job for group in scale_jobs.values() for job in group], repeat)
    scale = {key: scaling_rows(group) for key, group in scale_jobs.items()}
    lines = []
    if not args.no_multiproc:
        say("multiproc on the slider scene ...")
        lines = multiproc(streams.scenario("slider", duration, say), args.refractory)
    say(f"\n## 240x180, 1 ms steps, refractory {args.refractory} ({machine()}; {load()}; timing noise floor "
        f"p50/p99 {floor[0]:.1f}/{floor[1]:.1f} µs for a 30 µs computation)\n")
    say(main_table(rows))
    say(f"\nChip (paper): {CHIP_US_PER_STEP:.0f} µs per step at 240x180, ~100 µs at half resolution. "
        f"CPU methods the paper cites: {CPU_METHODS_EV_S[0] / 1e6:g}-{CPU_METHODS_EV_S[1] / 1e6:g} M ev/s.")
    say("\n## Resolution scaling, 1 M events/s\n")
    say(scaling_table(scale))
    if lines:
        say("\n## Multiproc backend, slider scene\n")
        say("\n".join(lines))
    say("\n## Targets\n")
    say(targets(rows, scale))


if __name__ == "__main__":
    main()
