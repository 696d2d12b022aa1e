"""Compile time against the number of cores: must be linear (issue 27, ``traffic_of``).

    python benchmarks/compile_scaling.py            # 3 rounds, ~1 minute

Compiles the paper's network with 1x1 patches (one core per pixel and layer) at 60x45
(2,700 cores per layer) and 240x180 (43,200, 16x more), several rounds each, and prints
the median time per core of each size and their ratio. Linear work gives a ratio near 1;
the quadratic ``traffic_of`` of before gave ~58 s at 240x180 (a ratio far above 2).
Target: ratio <= 2 (CPU time, so that a busy machine does not decide).
"""

from __future__ import annotations

import argparse
import statistics
import time

from tofnet.compiler import compile_network
from tofnet.networks import depth_network

SIZES = ((60, 45), (240, 180))


def per_core_us(size: tuple[int, int], rounds: int) -> float:
    """Median CPU µs per core of compiling the paper's network at ``size`` with 1x1 patches."""
    times = []
    for _ in range(rounds):
        network = depth_network(size)
        started = time.process_time()
        compiled = compile_network(network, patch=(1, 1))
        times.append((time.process_time() - started) / compiled.cores_used * 1e6)
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    small, large = (per_core_us(size, args.rounds) for size in SIZES)
    for (w, h), us in zip(SIZES, (small, large)):
        print(f"{w}x{h}: {w * h:6d} cores per layer, {us:6.1f} µs CPU per core (median of {args.rounds})")
    ratio = large / small
    print(f"ratio {ratio:.2f} (target <= 2: linear in the core count)")
    return 0 if ratio <= 2 else 1


if __name__ == "__main__":
    raise SystemExit(main())
