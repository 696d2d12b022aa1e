"""The paper's network built in Python, twice, and checked against examples/paper_240x180.yaml.

Run: ``python examples/build_paper_network.py``. It builds the network with the
ready-made ``tofnet.depth_network`` and by hand from the four processes and their
ports, asserts both equal the YAML spec, compiles it for Loihi 2 with 30x30 patches
and prints the mapping (48 + 48 = 96 cores on one chip).
"""

from __future__ import annotations

from pathlib import Path

from tofnet import DepthProcess, InputProcess, Network, TimeOfTravelProcess, VelocityProcess, depth_network
from tofnet.compiler import LOIHI2, compile_network
from tofnet.compiler.report import format_report
from tofnet.io.spec import dump_spec, load_spec, networks_equal

HERE = Path(__file__).resolve().parent


def by_hand() -> Network:
    """input -> time_of_travel -> depth <- velocity, port by port."""
    inp = InputProcess(name="input", sensor_size=(240, 180), timestep="1ms", refractory="60ms")
    tot = TimeOfTravelProcess(name="time_of_travel", distance=1, counter_bits=8)
    depth = DepthProcess(name="depth", min_depth=0.05, max_depth=20.0)
    velocity = VelocityProcess(name="velocity", source="groundtruth", per="patch", patch_size=30, update_every=1)
    inp.events.connect(tot.events)
    tot.counts.connect(depth.counts)
    velocity.a_t.connect(depth.a_t)
    return Network([inp, tot, depth, velocity], name="paper-240x180")


def main() -> None:
    spec = load_spec(HERE / "paper_240x180.yaml")
    ready_made = depth_network((240, 180), name="paper-240x180")
    hand_made = by_hand()
    assert networks_equal(ready_made, spec.network), "depth_network() differs from paper_240x180.yaml"
    assert networks_equal(hand_made, spec.network), "the hand-built network differs from paper_240x180.yaml"
    # The same network written back to YAML reads back equal.
    assert networks_equal(load_spec(dump_spec(hand_made)).network, hand_made)

    compiled = compile_network(hand_made, budget=LOIHI2, patch=(30, 30))
    assert [layer.cores for layer in compiled.layers] == [48, 48] and compiled.chips_used == 1
    print(format_report(compiled))


if __name__ == "__main__":
    main()
