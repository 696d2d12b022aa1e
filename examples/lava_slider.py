"""The paper's network in Lava: the `slider` scene (a camera sliding past a desk, 240x180) run as
Lava processes on Lava's CPU simulation of Loihi 2, next to tofnet's `fixed` backend.

    python examples/lava_slider.py          # in a Python 3.10 venv with tofnet[lava] (docs/lava.md); ~1 min

Prints how many depth estimates each gives, the first ones side by side, and that they are the same bytes.
"""

import tempfile
import time
from pathlib import Path

import numpy as np

from tofnet import depth_network
from tofnet.backends.lava_backend import require_lava
from tofnet.backends.registry import get_backend
from tofnet.errors import TofnetError
from tofnet.io import read_recording
from tofnet.sim.run import simulate

DURATION_S = 0.15  # 150 steps of 1 ms: Lava's Python runtime takes tens of ms per step at 240x180


def main() -> None:
    folder = Path(tempfile.mkdtemp(prefix="tofnet-lava-slider-")) / "slider"
    simulate("slider", folder, duration=DURATION_S, seed=0)
    recording = read_recording(folder)
    network = depth_network(recording.sensor_size)  # input -> time_of_travel -> depth <- velocity
    print(f"slider: {len(recording.events):,} events over {recording.duration * 1e3:.0f} ms, "
          f"{recording.sensor_size[0]}x{recording.sensor_size[1]}")

    results = {}
    for name in ("fixed", "lava"):
        started = time.perf_counter()
        results[name] = get_backend(name).run(network, recording)
        print(f"{name:>5}: {len(results[name].depth):,} depth estimates in {time.perf_counter() - started:.1f} s")
    fixed, lava = results["fixed"].depth, results["lava"].depth

    print("\nthe first estimates (the same on both):")
    print(f"{'step':>5} {'x':>4} {'y':>4} {'fixed z (m)':>12} {'lava z (m)':>12}")
    for a, b in zip(fixed[:8], lava[:8]):
        print(f"{a['step']:>5} {a['x']:>4} {a['y']:>4} {a['z']:>12.6f} {b['z']:>12.6f}")
    print(f"median depth: fixed {np.median(fixed['z']):.4f} m, lava {np.median(lava['z']):.4f} m")
    same = fixed.tobytes() == lava.tobytes() and results["fixed"].counts == results["lava"].counts
    print(f"byte-identical estimates and counts: {same}")
    if not same:
        raise SystemExit("lava and fixed differ")


if __name__ == "__main__":
    try:
        require_lava()  # before simulating: without Lava here, the one line saying how to get it
    except TofnetError as err:
        raise SystemExit(f"lava_slider.py: {err}") from None
    main()
