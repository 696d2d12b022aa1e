"""What two bands cost beyond one worker: `fixed`, its 2 bands run one after the other in one thread.

    python benchmarks/band_cost.py [--rounds 5] [--streams slider,edges20] [--networks "paper,time surface"]
    python benchmarks/band_cost.py --instructions 1000000 [--streams ...]    # callgrind, a few minutes

On a machine shared with other jobs the wall time of 2 threads says little, and CPU time of
threads running side by side mixes in what the other jobs do to them; run one after the other,
the bands' CPU time is their own work. Per stream and network: process CPU ms of one worker and
of 2 bands (median over the rounds, with their range), and the CPU ms (median) of each part of
the run, timed in the thread that runs it, net of the parts it calls:

- paper network: the bands' listings (``select_rows``), their kernels (``TimeOfTravelKernel.run_events``,
  all bands), the merge (``merge_share``, ``merged_by_step``) and the rest of ``BandedKernel.run_events``
  (its Python);
- time surface: the bands' ``feed`` (each keeps its rows' events: ``TimeSurfaceModel._columns``),
  their estimators (``TimeSurfaceEstimator.feed_columns``), the rest of each model's ``run`` (its
  events taken, its records sorted), the merge of their records and the rest of ``BandedReader.run``.

``--instructions N``: instead, the instructions of one run of the first ``N`` events of each
stream, one worker and 2 bands, counted by valgrind's callgrind around ``run`` alone (in a process
that ran it once before, natively compiled into numba's cache for generic x86-64 first), as
``benchmarks/time_surface_instructions.py`` does: a figure this shared machine cannot disturb.

Streams: ``slider`` (the simulated scene, 0.5 s repeated 10 times, 240x180), ``edges20`` and
``edges50`` (1280x720 at 20 / 50 M ev/s, ``--duration`` s). docs/performance.md, "Workers".
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import streams  # noqa: E402
from scaling import networks, repeated  # noqa: E402

from tofnet.io.recording import Recording  # noqa: E402

import tofnet.backends.bands as bands  # noqa: E402
import tofnet.backends.local as local  # noqa: E402
from tofnet.backends.registry import get_backend  # noqa: E402
from tofnet.compiler import compile_network  # noqa: E402
from tofnet.kernels.region import TimeOfTravelKernel  # noqa: E402
from tofnet.kernels.time_surface_estimator import TimeSurfaceEstimator  # noqa: E402
from tofnet.models.time_surface import TimeSurfaceModel  # noqa: E402

#: (owner, attribute, part): what is timed, in the thread that runs it.
PARTS = ((bands, "select_rows", "listing"), (TimeOfTravelKernel, "run_events", "kernels"),
         (bands, "merge_share", "merge"), (bands, "merged_by_step", "merge"), (bands.BandedKernel, "run_events", "bands' run"),
         (bands.BandedReader, "feed", "feed"), (TimeSurfaceEstimator, "feed_columns", "kernels"),
         (bands.BandedReader, "run", "bands' run"), (TimeSurfaceModel, "run", "models' run"))


class Parts:
    """While active, the thread CPU time spent in each of ``PARTS`` (s, summed over calls), each net of
    the parts it calls (the rest of ``BandedKernel.run_events`` is its Python and hand-overs)."""

    def __init__(self):
        self.spent: dict[str, float] = {}
        self._saved = []
        self._local = threading.local()

    def __enter__(self):
        for owner, name, part in PARTS:
            original = getattr(owner, name)
            self._saved.append((owner, name, original))
            setattr(owner, name, self._timed(original, part))
        return self

    def _timed(self, fn, part):
        spent, local = self.spent, self._local

        def timed(*args, **kwargs):
            stack = local.__dict__.setdefault("stack", [])
            stack.append(0.0)  # time of the parts it calls
            start = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                total = time.thread_time() - start
                inner = stack.pop()
                spent[part] = spent.get(part, 0.0) + total - inner
                if stack:
                    stack[-1] += total
        return timed

    def __exit__(self, *exc):
        for owner, name, original in reversed(self._saved):
            setattr(owner, name, original)


def recordings(names: list[str], duration: float) -> dict:
    out = {}
    for name in names:
        if name == "slider":
            out["slider x10"] = repeated(streams.scenario("slider", 0.5, lambda *a: None), 10)
        elif name in ("edges20", "edges50"):
            out[f"edges 1280x720 {name[5:]}M"] = streams.edges((1280, 720), float(name[5:]) * 1e6, duration)
        else:
            raise SystemExit(f"band_cost: unknown stream {name!r} (slider, edges20, edges50)")
    return out


def counted(stream: str, kind: str, workers: int, events: int) -> float:
    """Instructions (callgrind) of one ``run`` of the first ``events`` of ``stream``, bands one after the other."""
    inner = [str(Path(__file__).resolve()), "--inner", f"{stream}:{kind}:{workers}:{events}"]
    env = {**os.environ, "NUMBA_CPU_NAME": "generic"}
    subprocess.run([sys.executable, *inner, "--no-toggle"], check=True, env=env)  # compile into numba's cache
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}",
                        sys.executable, *inner], check=True, capture_output=True, env=env)
        totals = next(line for line in out.read_text().splitlines() if line.startswith("totals:"))
    return float(totals.split()[1])


def run_inner(spec: str, toggle: bool) -> None:
    """One run of ``stream:network:workers:events`` after a first one, counted alone when ``toggle``."""
    stream, kind, workers, events = spec.split(":")
    recording = next(iter(recordings([stream], 0.25).values()))
    recording = Recording(recording.events[:int(events)].copy(), intrinsics=recording.intrinsics,
                          trajectory=recording.trajectory, sensor_size=recording.sensor_size)
    compiled = compile_network(networks(recording.sensor_size, recording)[kind])
    get_backend("fixed", workers=int(workers)).run(compiled, recording)  # loads the kernels outside the count
    switch = ["callgrind_control", "-i"]
    if toggle:
        subprocess.run([*switch, "on", str(os.getpid())], check=True, capture_output=True)
    get_backend("fixed", workers=int(workers)).run(compiled, recording)
    if toggle:
        subprocess.run([*switch, "off", str(os.getpid())], check=True, capture_output=True)


def instructions(args) -> int:
    if shutil.which("valgrind") is None or shutil.which("callgrind_control") is None:
        print("band_cost: valgrind (with callgrind_control) not found", file=sys.stderr)
        return 2
    print(f"| stream (first {args.instructions:,} events) | network | one worker (M instructions) | 2 bands | 2 vs 1 |")
    print("| --- | --- | --- | --- | --- |")
    for stream in args.streams.split(","):
        for kind in args.networks.split(","):
            one, two = (counted(stream, kind, w, args.instructions) / 1e6 for w in (1, 2))
            print(f"| {stream} | {kind} | {one:.1f} | {two:.1f} | {two / one:.3f}x |", flush=True)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--streams", default="slider")
    parser.add_argument("--networks", default="paper,time surface")
    parser.add_argument("--duration", type=float, default=0.25, help="seconds of each edges stream")
    parser.add_argument("--instructions", type=int, default=0, help="count instructions of the first N events")
    parser.add_argument("--inner", default="", help=argparse.SUPPRESS)
    parser.add_argument("--no-toggle", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    local.threads_for = lambda count: 1  # every band in the caller's thread, one after the other
    if args.inner:
        run_inner(args.inner, not args.no_toggle)
        return 0
    if args.instructions:
        return instructions(args)
    print("| stream | network | one worker (CPU ms): its parts | 2 bands (CPU ms): their parts | 2 vs 1 |")
    print("| --- | --- | --- | --- | --- |")
    for name, recording in recordings(args.streams.split(","), args.duration).items():
        for kind, network in networks(recording.sensor_size, recording).items():
            if kind not in args.networks.split(","):
                continue
            compiled = compile_network(network)
            for workers in (1, 2):
                get_backend("fixed", workers=workers).run(compiled, recording)  # compile or load the kernels
            cpu: dict[int, list[float]] = {1: [], 2: []}
            parts: dict[int, dict[str, list[float]]] = {1: {}, 2: {}}
            for _ in range(args.rounds):
                for workers in (1, 2):
                    with Parts() as timed:
                        start = time.process_time()
                        get_backend("fixed", workers=workers).run(compiled, recording)
                        cpu[workers].append(time.process_time() - start)
                    for part, spent in timed.spent.items():
                        parts[workers].setdefault(part, []).append(spent)
            one, two = (statistics.median(cpu[w]) for w in (1, 2))
            text = {w: ", ".join(f"{part} {1e3 * statistics.median(v):.0f}" for part, v in parts[w].items())
                    for w in (1, 2)}
            print(f"| {name} | {kind} | {1e3 * one:.0f} ({1e3 * min(cpu[1]):.0f}-{1e3 * max(cpu[1]):.0f}): {text[1]} | "
                  f"{1e3 * two:.0f} ({1e3 * min(cpu[2]):.0f}-{1e3 * max(cpu[2]):.0f}): {text[2]} | {two / one:.2f}x |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
