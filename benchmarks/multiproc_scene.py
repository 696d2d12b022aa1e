"""The multiproc backend on a whole 240x180 scene: bit-identity with ``fixed`` and timings.

    python benchmarks/multiproc_scene.py [--duration 0.3] [--workers 1 2]

Simulates the ``slider`` scenario, compiles the paper's mapping (30x30 patches, 48 + 48
cores), runs ``fixed`` once and ``multiproc`` in one session per worker count (two runs
each, to separate start-up from steady state), and checks that every depth estimate and
time-of-travel spike is identical. Numbers quoted in docs/backends.md come from here.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from tofnet.backends.event_driven import FixedBackend
from tofnet.backends.multiproc import MultiprocBackend
from tofnet.compiler import compile_network
from tofnet.networks import depth_network
from tofnet.sim.engine import generate
from tofnet.sim.scenarios import scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=0.3, help="seconds of the slider scenario")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()

    recording = generate(scenario("slider", args.duration), seed=0).to_recording()
    compiled = compile_network(depth_network((240, 180)), patch=(30, 30))
    print(f"slider {args.duration:g} s: {len(recording.events):,} events, {compiled.cores_used} cores")
    fixed = FixedBackend().run(compiled, recording, record_tot=True)
    order = np.lexsort((fixed.depth["x"], fixed.depth["y"], fixed.depth["step"]))
    tot_order = np.lexsort((fixed.tot["direction"], fixed.tot["x"], fixed.tot["y"], fixed.tot["step"]))
    print(f"fixed      {fixed.wall_time:7.3f} s   {len(fixed.depth):,} estimates")
    for workers in args.workers:
        started = time.perf_counter()
        with MultiprocBackend(workers=workers).session(compiled) as session:
            first = session.run(recording, record_tot=True)
            second = session.run(recording, record_tot=True)
        total = time.perf_counter() - started
        same = (first.depth.tobytes() == fixed.depth[order].tobytes()
                and first.tot.tobytes() == fixed.tot[tot_order].tobytes()
                and first.rejected == fixed.rejected and second.depth.tobytes() == first.depth.tobytes())
        print(f"multiproc  {workers} worker(s): start-up {session.startup_seconds:.2f} s, runs {first.wall_time:.3f} s "
              f"and {second.wall_time:.3f} s, {total:.2f} s in all; bit-identical to fixed: {same}")


if __name__ == "__main__":
    main()
