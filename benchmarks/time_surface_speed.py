"""Speed of the time-surface estimator on scenes and fixed-rate streams (run by hand, not in CI).

    python benchmarks/time_surface_speed.py                 # about 3 min
    python benchmarks/time_surface_speed.py --streams slider,edges:1e6 --rounds 5
    python benchmarks/time_surface_speed.py --before ''      # without the "before" columns

For each stream (``benchmarks/streams.py``: the simulator's scenes, 1 s, and the synthetic
``uniform`` and ``edges`` streams at a given rate, 240x180): CPU time of the estimator
fed the whole stream in one packet and in 1 ms packets (the per-packet wall time's mean
and 99th percentile too), the share of events that are first events (each costs a fit),
and, measured in the same rounds for comparison, the paper network's fused kernel
(``FixedBackend`` stream, ``run``'s packets). Best of ``--rounds`` rounds; CPU time, not
wall time, since the machine is shared. ``--before`` (default ``window_px=0;iterations=3``, the
defaults before ``window_px``: the window from the scene's depth scale only) is
measured in the same rounds, one packet, for a before/after comparison. Text then markdown.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import streams  # noqa: E402
from accuracy import fmt, log, print_tables  # noqa: E402
from performance import bulk_once, machine, network, packets  # noqa: E402
from time_surface_runs import config_for, trajectory_rows  # noqa: E402
from time_surface_sweep import parse_assignments  # noqa: E402
from tofnet.kernels.time_surface_estimator import TimeSurfaceEstimator  # noqa: E402

STREAMS = ("slider,fast_slider,all_axes,room_slider,forward,uniform:1e6,edges:1e6,uniform:5e6,edges:5e6,uniform:1e7,"
           "edges:1e7,uniform:2e7,edges:2e7")


def recording_of(spec: str):
    if ":" in spec:
        kind, rate = spec.split(":")
        return getattr(streams, kind)((240, 180), float(rate), 1.0)
    return streams.scenario(spec, 1.0, log)


#: The configuration the speeds are compared with unless ``--before`` says another.
BEFORE = "window_px=0;iterations=3"


def estimator_for(recording, **changes):
    config = config_for(recording, **changes)
    t0 = int(recording.events["t"][0])
    return TimeSurfaceEstimator(config, t0), trajectory_rows(recording, t0, config)


def bulk(recording, **changes) -> tuple[float, TimeSurfaceEstimator]:
    estimator, rows = estimator_for(recording, **changes)
    gc.collect()
    started = time.process_time()
    estimator.feed(recording.events, rows)
    return time.process_time() - started, estimator


def in_packets(recording, parts) -> tuple[float, np.ndarray]:
    estimator, rows = estimator_for(recording)
    seconds = np.empty(len(parts))
    gc.collect()
    started = time.process_time()
    for i, part in enumerate(parts):
        wall = time.perf_counter()
        estimator.feed(part, rows)
        seconds[i] = time.perf_counter() - wall
    return time.process_time() - started, seconds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--streams", default=STREAMS)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--before", default=BEFORE,
                        help="'name=value;...': the configuration to compare with ('' for none)")
    args = parser.parse_args(argv)
    before = parse_assignments(args.before)
    specs = [s for s in args.streams.split(",") if s]
    recordings = {s: recording_of(s) for s in specs}
    best: dict[str, dict] = {s: {} for s in specs}
    for r in range(args.rounds):
        log(f"round {r + 1}/{args.rounds}")
        for spec in specs:
            rec = recordings[spec]
            net = network(rec.sensor_size, "60ms")
            if r == 0:  # compile and warm up
                bulk(rec)
                bulk_once(net, rec)
            cpu, estimator = bulk(rec)
            if before:
                old_cpu, old = bulk(rec, **before)
            packet_cpu, packet_wall = in_packets(rec, packets(rec))
            paper = bulk_once(net, rec)
            b = best[spec]
            if not b or cpu < b["cpu"]:
                b.update(cpu=cpu, first=estimator.first_events, emitted=estimator.emitted)
            if before and ("old_cpu" not in b or old_cpu < b["old_cpu"]):
                b.update(old_cpu=old_cpu, old_first=old.first_events, old_emitted=old.emitted)
            if "packet_cpu" not in b or packet_cpu < b["packet_cpu"]:
                b.update(packet_cpu=packet_cpu, p_mean=packet_wall.mean() * 1e6,
                         p99=np.percentile(packet_wall, 99) * 1e6)
            b["paper"] = min(b.get("paper", np.inf), paper)
    header = ["stream", "events", "first events %", "estimates %", "M ev/s (one packet)", "M ev/s (1 ms packets)",
              "µs per 1 ms packet (mean / p99)", "ns per first event", "paper network M ev/s", "paper / estimator"]
    if before:
        header += [f"before ({args.before}): first events %", "estimates %", "M ev/s", "speed-up"]
    rows = []
    for spec in specs:
        n, b = len(recordings[spec].events), best[spec]
        rows.append([spec, fmt(n), fmt(100 * b["first"] / n), fmt(100 * b["emitted"] / n), fmt(n / b["cpu"] / 1e6),
                     fmt(n / b["packet_cpu"] / 1e6), f"{b['p_mean']:.0f} / {b['p99']:.0f}",
                     fmt(b["cpu"] / max(b["first"], 1) * 1e9, 0), fmt(n / b["paper"] / 1e6),
                     fmt(b["cpu"] / b["paper"], 1)])
        if before:
            rows[-1] += [fmt(100 * b["old_first"] / n), fmt(100 * b["old_emitted"] / n), fmt(n / b["old_cpu"] / 1e6),
                         fmt(b["old_cpu"] / b["cpu"], 2)]
    print_tables(header, rows, f"Time-surface estimator speed (defaults), best of {args.rounds} rounds, CPU time; "
                 f"{machine()}")
    print("reproduce: python benchmarks/time_surface_speed.py" + (f" --streams {args.streams}"
                                                                   if args.streams != STREAMS else "")
          + (f" --before '{args.before}'" if args.before != BEFORE else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
