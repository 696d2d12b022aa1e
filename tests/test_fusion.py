"""Fusion is an optimisation: the fused paper chain equals its models run one by one, bit for bit."""

import pytest

from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.backends.fusion import paper_chain
from tofnet.compiler import compile_network
from tofnet.conformance import CASES
from tofnet.conformance.compare import compare
from tofnet.networks import depth_network

FUSED_CASES = [c for c in CASES if paper_chain(c.build().network, "fixed") is not None]


def test_most_cases_are_the_paper_chain():
    assert len(FUSED_CASES) >= 40


@pytest.mark.parametrize("case", FUSED_CASES, ids=lambda c: c.name)
@pytest.mark.parametrize("backend", [FixedBackend, FloatBackend])
def test_fused_equals_unfused_on_the_conformance_inputs(case, backend):
    scene = case.build()
    compiled = compile_network(scene.network, patch=scene.patch)
    fused = backend().run(compiled, scene.recording, record_tot=True)
    unfused = backend(fuse=False).run(compiled, scene.recording, record_tot=True)
    comparison = compare(fused, unfused, "exact", scene.network)  # every output and count, bit for bit
    assert comparison.ok, comparison.first


def test_fused_equals_unfused_on_a_whole_simulated_scene():
    from tofnet.sim.engine import generate
    from tofnet.sim.scenarios import scenario

    recording = generate(scenario("slider", 0.2), seed=0).to_recording()
    net = depth_network((240, 180))
    fused = FixedBackend().run(net, recording, record_tot=True)
    unfused = FixedBackend(fuse=False).run(net, recording, record_tot=True)
    assert len(fused.depth) > 10_000
    assert compare(fused, unfused, "exact", net).ok
    assert fused.depth.tobytes() == unfused.depth.tobytes() and fused.tot.tobytes() == unfused.tot.tobytes()


@pytest.mark.parametrize("timestep", ["9ms", 0.009])
def test_fused_and_unfused_take_the_timestep_from_the_same_microseconds(timestep):
    """"9ms" parses to 0.009000000000000001 s, not 0.009: both paths read the clock's whole µs
    (9000) through the one conversion, so their depths agree to the bit and do not depend on how
    the timestep was written (the fused float path once used the parsed seconds: last-bit differences)."""
    from tofnet.sim.engine import generate
    from tofnet.sim.scenarios import scenario

    recording = generate(scenario("slider", 0.1), seed=0).to_recording()
    net = depth_network((240, 180), input={"timestep": timestep}, velocity={"per": "pixel"})
    fused = FloatBackend().run(net, recording)
    unfused = FloatBackend(fuse=False).run(net, recording)
    assert len(fused.depth) > 1_000 and fused.timestep_us == 9000
    assert fused.depth.tobytes() == unfused.depth.tobytes()
    written_plainly = FloatBackend().run(depth_network((240, 180), input={"timestep": 0.009},
                                                       velocity={"per": "pixel"}), recording)
    assert fused.depth.tobytes() == written_plainly.depth.tobytes()
