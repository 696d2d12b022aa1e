"""Events per second of the event-driven backends on random events (run by hand, not a test).

    python benchmarks/event_driven_speed.py [n_events] [backend] [refractory]

Random events at 240x180, uniformly spread over time at 1 M events/s, 1 ms steps,
refractory 5 ms unless given (random pixels fire every 43 ms on average, so 5 ms keeps
~90 % of the events: a harder load than the longer default). Prints the CPU time and
events/s of ``run`` (input filter + kernel + output assembly), best of 5 after a warm-up
run that compiles; CPU time, because wall time on a shared machine measures the neighbours.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.events import make_events
from tofnet.io.recording import Recording
from tofnet.networks import depth_network
from tofnet.testing import TEST_INTRINSICS


def random_recording(n: int, sensor=(240, 180), rate: float = 1e6, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, int(n / rate * 1e6), n))
    events = make_events(t, rng.integers(0, sensor[0], n), rng.integers(0, sensor[1], n), rng.integers(0, 2, n))
    return Recording(events, intrinsics=TEST_INTRINSICS, sensor_size=sensor)


def main() -> None:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 5_000_000
    backend = {"fixed": FixedBackend, "float": FloatBackend}[sys.argv[2] if len(sys.argv) > 2 else "fixed"]()
    refractory = sys.argv[3] if len(sys.argv) > 3 else "5ms"
    net = depth_network((240, 180), input={"refractory": refractory},
                        velocity={"source": "constant", "velocity": [-0.5, 0.0, 0.1]})
    backend.run(net, random_recording(10_000))  # compile
    recording = random_recording(n)
    # CPU time, best of 5: wall time is unreliable on a shared machine.
    cpu = []
    for _ in range(5):
        started = time.process_time()
        result = backend.run(net, recording)
        cpu.append(time.process_time() - started)
    best = min(cpu)
    print(f"{backend.name}: {n} events in {best:.3f} s CPU = {n / best / 1e6:.1f} M events/s "
          f"(best of 5; refractory {refractory}, accepted {result.accepted}, tot spikes {result.tot_spikes}, "
          f"depth {len(result.depth)}, rejected {result.rejected})")


if __name__ == "__main__":
    main()
