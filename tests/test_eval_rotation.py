"""Depth recomputed offline from time-of-travel spikes with eq. 7 / eq. 8 (tofnet/eval/rotation.py)."""

from __future__ import annotations

import numpy as np
import pytest

from tofnet.events import TOT_DTYPE
from tofnet.eval.rotation import as_depth_array, depth_inputs, recompute_depth, share_split
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording
from tofnet.io.rotation import ConstantAngularVelocity
from tofnet.networks import depth_network
from tofnet.testing import LinearVelocity, moving_pattern, run_network

SIZE = (32, 24)
K = Intrinsics(200.0, 200.0, 15.5, 11.5)


def tot(rows):
    out = np.zeros(len(rows), dtype=TOT_DTYPE)
    for i, row in enumerate(rows):
        out[i] = row
    return out


def test_depth_inputs_follow_the_depth_neuron_rules():
    spikes = tot([(5, 3, 2, 0, 4), (5, 3, 2, 1, 6), (5, 3, 2, 2, 3), (5, 3, 2, 3, 3),  # +u wins, v tie
                  (5, 4, 2, 1, 2),  # -u only
                  (7, 3, 2, 3, 9)])  # -v only, later step
    inputs = depth_inputs(spikes, SIZE[0])
    got = sorted(zip(inputs.step, inputs.x, inputs.y, inputs.signed_x, inputs.signed_y))
    assert got == [(6, 3, 2, 4, 0), (6, 4, 2, -2, 0), (8, 3, 2, 0, -9)]


def run(events, trajectory):
    recording = Recording(events, intrinsics=K, sensor_size=SIZE, trajectory=trajectory)
    net = depth_network(SIZE, input={"refractory": 0}, velocity={"per": "pixel"})
    return recording, run_network(net, recording, backend="float", record_tot=True)


def test_eq8_at_network_timing_reproduces_the_network():
    events = moving_pattern(SIZE, (-60.0, 25.0), 300_000, seed=1)
    trajectory = LinearVelocity((0.4, -0.1, 0.05), (0.8, -0.3, 0.0), 0.3)
    recording, result = run(events, trajectory)
    inputs = depth_inputs(result.tot, SIZE[0])
    timing = {"t0_us": result.t0_us, "timestep_us": result.timestep_us}
    z, share = recompute_depth(inputs, intrinsics=K, velocity=trajectory, when="network", **timing)
    np.testing.assert_array_equal(share, 1.0)
    keep = inputs.measured & (z > 0.05) & (z < 20.0)
    mine = np.sort(as_depth_array(inputs, z, keep, **timing), order=["step", "y", "x"])
    theirs = np.sort(result.depth, order=["step", "y", "x"])
    assert len(mine) == len(theirs) > 100
    np.testing.assert_array_equal(mine[["t", "x", "y", "step"]], theirs[["t", "x", "y", "step"]])
    np.testing.assert_allclose(mine["z"], theirs["z"], rtol=1e-12)


@pytest.mark.parametrize("when", ["trigger", "interval"])
def test_eq7_recovers_the_depth_of_a_turning_camera(when):
    # A plane 2 m away, camera sliding at 0.5 m/s and turning at 0.1 rad/s about y: the image
    # moves at -200*0.5/2 - 200*0.1 = -70 px/s (x^2/f adds < 0.2 px/s on this sensor), of which
    # translation is 50/70.
    events = moving_pattern(SIZE, (-70.0, 0.0), 400_000, seed=2)
    velocity, omega = ConstantVelocity((0.5, 0.0, 0.0)), ConstantAngularVelocity((0.0, 0.1, 0.0))
    recording, result = run(events, velocity)
    inputs = depth_inputs(result.tot, SIZE[0])
    timing = {"t0_us": result.t0_us, "timestep_us": result.timestep_us}
    z7, share = recompute_depth(inputs, intrinsics=K, velocity=velocity, angular=omega, when=when, **timing)
    z8, _ = recompute_depth(inputs, intrinsics=K, velocity=velocity, when=when, **timing)
    horizontal = inputs.measured & (inputs.signed_x != 0) & (share > 0)
    assert horizontal.sum() > 200
    assert np.median(z7[horizontal]) == pytest.approx(2.0, rel=0.05)
    assert np.median(z8[horizontal]) == pytest.approx(2.0 * 50 / 70, rel=0.05)
    assert np.median(share[horizontal]) == pytest.approx(50 / 70, rel=0.05)


def test_share_split_bins():
    share = np.array([0.05, 0.2, 0.3, 0.4, 1.0, 1.0, 2.0])
    rel = np.array([1.0, -0.5, 0.1, 0.3, -0.1, 0.2, 0.01])
    rows = share_split(share, rel, edges=(0.0, 0.25, 0.5, 1.5, np.inf))
    assert [r["n"] for r in rows] == [2, 2, 2, 1]
    assert rows[1]["median_rel"] == pytest.approx(0.2) and rows[1]["bias"] == pytest.approx(0.2)
    assert rows[2]["rel_times_share"] == pytest.approx(0.15)
    assert share_split(share, rel, edges=(5.0, 6.0))[0]["n"] == 0
