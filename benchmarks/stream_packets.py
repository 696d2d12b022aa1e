"""Streams with two workers against one, by packet size: where bands start to pay (by hand, not in CI).

    python benchmarks/stream_packets.py                    # both networks, edges 1280x720 at 20 M ev/s
    python benchmarks/stream_packets.py --rate 5e7 --sizes 16384,65536 --networks paper

A stream (``open_stream``) is fed packets of a fixed number of events; per packet the mean wall
time of ``feed_all`` (the canonical order, what a live session asks for) and, for the paper's
chain, of ``feed`` (the trigger events' order, which one kernel need not sort), with one worker
and with two whose bands are forced on (``one_band_below`` 0; a graph stream, the time surface's
or the paper's chain model by model, ``paper unfused``, always runs its bands). Each round runs every configuration once, alternating; medians over the
rounds, after one untimed round (numba's kernels loaded or compiled). The sizes where two workers reach
one worker's time set ``bands.FUSED_BANDS_FROM`` (docs/performance.md, "Streams: packet size"). Markdown
to stdout.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import streams  # noqa: E402

import numpy as np  # noqa: E402

from tofnet.backends.registry import get_backend  # noqa: E402
from tofnet.core.network import Network  # noqa: E402
from tofnet.io.recording import Recording  # noqa: E402
from tofnet.networks import depth_network, improved_network  # noqa: E402


def per_packet_us(network: Network, recording: Recording, parts: list[np.ndarray], workers: int, call: str,
                  fuse: bool | None = None) -> float:
    """Mean wall µs of ``call`` over ``parts`` (the first three not timed: the kernels' state is built)."""
    stream = get_backend("fixed", workers=workers).open_stream(network, recording=recording, fuse=fuse)
    if workers > 1 and hasattr(getattr(stream, "kernel", None), "one_band_below"):
        stream.kernel.one_band_below = 0
    feed = getattr(stream, call)
    for part in parts[:3]:
        feed(part)
    start = time.perf_counter()
    for part in parts[3:]:
        feed(part)
    took = (time.perf_counter() - start) / (len(parts) - 3) * 1e6
    stream.close()
    return took


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=2e7, help="events/s of the edges stream (default 2e7)")
    parser.add_argument("--sizes", default="8192,16384,32768,65536,131072,262144", help="events per packet")
    parser.add_argument("--networks", default="paper,time surface")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    sensor = (1280, 720)
    sizes = [int(s) for s in args.sizes.split(",")]
    recording = streams.edges(sensor, args.rate, max(0.3, 43 * max(sizes) / args.rate))
    velocity = {"source": "constant", "velocity": list(streams.SYNTHETIC_VELOCITY)}
    networks = {"paper": depth_network(sensor, velocity=velocity),
                "paper unfused": depth_network(sensor, velocity=velocity),
                "time surface": improved_network(sensor, velocity={**velocity, "per": "pixel"})}
    print(f"# {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; edges 1280x720 at {args.rate:g} events/s")
    print("\n| network | call | events per packet | 1 worker µs | 2 workers µs | 2 vs 1 |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    events = recording.events
    unknown = [k for k in args.networks.split(",") if k not in networks]
    if unknown:
        parser.error(f"--networks: unknown {', '.join(unknown)}; choose from {', '.join(networks)}")
    for kind in args.networks.split(","):
        for call in ("feed_all", "feed") if kind == "paper" else ("feed_all",):
            for size in sizes:
                parts = [events[i:i + size] for i in range(0, min(len(events), size * 43), size)]
                times: dict[int, list[float]] = {1: [], 2: []}
                for workers in (1, 2):  # untimed: numba's kernels loaded (or compiled) for this configuration
                    per_packet_us(networks[kind], recording, parts[:4], workers, call,
                                  False if kind == "paper unfused" else None)
                for _ in range(args.rounds):
                    for workers in (1, 2):
                        times[workers].append(per_packet_us(networks[kind], recording, parts, workers, call,
                                                            False if kind == "paper unfused" else None))
                one, two = statistics.median(times[1]), statistics.median(times[2])
                print(f"| {kind} | `{call}` | {size:,} | {one:,.0f} | {two:,.0f} | {one / two:.2f}x |", flush=True)
    print(f"\nreproduce: python benchmarks/stream_packets.py --rate {args.rate:g} --sizes {args.sizes} "
          f"--rounds {args.rounds}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
