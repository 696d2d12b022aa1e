"""What two threads of this machine can give at best, whatever tofnet does.

Three loops with nothing to share, each compiled with numba and free of the GIL, are run
by one thread and then by N threads at once (each thread its own copy of the work):

- ``compute``: integer arithmetic in registers (no memory traffic): N threads give N x
  unless the "cores" are hyper-threads of one physical core or the host over-commits them;
- ``wide``: the same arithmetic in four independent chains per iteration, so that one thread
  can keep the core's execution ports busy: two threads on two hyper-threads of one physical
  core (which a virtual machine need not tell its guest) share those ports and give far less
  than 2x here while ``compute``, latency-bound, still gives ~2x;
- ``random_l2``: read-modify-write at random places of a private 1 MB table (the fused kernel's
  state on a 240x180 sensor is 1.4 MB): a core's own L2;
- ``random``: the same in a private 64 MB table (the fused kernels' per-pixel state on a
  1280x720 sensor is of that size): cache misses to memory;
- ``stream``: a sequential sum over a private 256 MB array: memory bandwidth.

The speed-up printed is N x one thread's time over the N threads' wall time (medians of
``--rounds``, single and parallel runs alternating). The bands of ``fixed --workers N``
cannot scale beyond these figures on the same machine (docs/performance.md, "Workers").

    python benchmarks/machine_ceiling.py --threads 2 --rounds 7
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def compute(n: int) -> int:
    x = np.uint64(88172645463325252)
    acc = np.uint64(0)
    for _ in range(n):
        x ^= x << np.uint64(13)
        x ^= x >> np.uint64(7)
        x ^= x << np.uint64(17)
        acc += x * np.uint64(2654435761)
    return acc


@njit(nogil=True, cache=True)
def wide(n: int) -> int:
    a = np.uint64(88172645463325252)
    b = np.uint64(0x9E3779B97F4A7C15)
    c = np.uint64(0xBF58476D1CE4E5B9)
    d = np.uint64(0x94D049BB133111EB)
    for _ in range(n):
        a ^= a << np.uint64(13)
        b ^= b << np.uint64(13)
        c ^= c << np.uint64(13)
        d ^= d << np.uint64(13)
        a ^= a >> np.uint64(7)
        b ^= b >> np.uint64(7)
        c ^= c >> np.uint64(7)
        d ^= d >> np.uint64(7)
        a ^= a << np.uint64(17)
        b ^= b << np.uint64(17)
        c ^= c << np.uint64(17)
        d ^= d << np.uint64(17)
    return a ^ b ^ c ^ d


@njit(nogil=True, cache=True)
def random_updates(table: np.ndarray, n: int) -> int:
    x = np.uint64(0x9E3779B97F4A7C15)
    mask = np.uint64(table.shape[0] - 1)
    for _ in range(n):
        x ^= x << np.uint64(13)
        x ^= x >> np.uint64(7)
        x ^= x << np.uint64(17)
        i = x & mask
        table[i] += np.int64(1)
    return table[0]


@njit(nogil=True, cache=True)
def stream_sum(array: np.ndarray) -> int:
    total = np.int64(0)
    for v in array:
        total += v
    return total


def _jobs(threads: int) -> dict[str, list]:
    tables = [np.zeros(1 << 23, np.int64) for _ in range(threads)]  # 64 MB each
    small = [np.zeros(1 << 17, np.int64) for _ in range(threads)]  # 1 MB each
    arrays = [np.ones(1 << 25, np.int64) for _ in range(threads)]  # 256 MB each
    return {
        "compute": [lambda: compute(200_000_000)] * threads,
        "wide": [lambda: wide(100_000_000)] * threads,
        "random_l2": [(lambda t=t: random_updates(t, 50_000_000)) for t in small],
        "random": [(lambda t=t: random_updates(t, 20_000_000)) for t in tables],
        "stream": [(lambda a=a: [stream_sum(a) for _ in range(4)]) for a in arrays],
    }


def _timed(pool: ThreadPoolExecutor, jobs: list) -> float:
    begun = time.perf_counter()
    for future in [pool.submit(job) for job in jobs]:
        future.result()
    return time.perf_counter() - begun


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    jobs = _jobs(args.threads)
    with ThreadPoolExecutor(args.threads) as pool:
        for work in jobs.values():  # compile and touch every page once
            _timed(pool, work)
        print(f"{args.threads} threads, {args.rounds} rounds, load average {os.getloadavg()[0]:.1f} at the start")
        print(f"{'loop':8s} {'one thread s':>13s} {'N threads s':>12s} {'speed-up':>9s} {'range':>13s}")
        for name, work in jobs.items():
            ratios, ones, alls = [], [], []
            for _ in range(args.rounds):
                one = _timed(pool, work[:1])
                every = _timed(pool, work)
                ones.append(one)
                alls.append(every)
                ratios.append(args.threads * one / every)
            print(f"{name:8s} {statistics.median(ones):13.3f} {statistics.median(alls):12.3f} "
                  f"{statistics.median(ratios):8.2f}x {min(ratios):6.2f}-{max(ratios):.2f}x")
        print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
