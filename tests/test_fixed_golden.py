"""The hand-checkable golden vectors of tests/golden/fixed_point.json (docs/fixed_point.md)."""

import json
from pathlib import Path

import numpy as np
import pytest

from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.backends.fusion import pipeline_of
from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Recording
from tofnet.kernels.fixed_point import FixedPointFormat, depth_tolerance, fixed_depth, quantize
from tofnet.kernels.region import TimeOfTravelKernel
from tofnet.networks import depth_network
from tofnet.testing import TEST_INTRINSICS, step_events

GOLDEN = json.loads((Path(__file__).parent / "golden" / "fixed_point.json").read_text())
CASES = {case["name"]: case for case in GOLDEN["network"]}


@pytest.mark.parametrize("case", GOLDEN["quantize"], ids=lambda c: c["comment"])
def test_quantize(case):
    assert quantize(case["value"], case["frac_bits"], case["payload_bits"]) == case["raw"]


@pytest.mark.parametrize("case", GOLDEN["depth"], ids=lambda c: c["comment"])
def test_fixed_depth(case):
    args = case["s_x"], case["s_y"], case["w_x"], case["w_y"], case["payload_bits"]
    assert fixed_depth(*args) == case["z_raw"]


def network(case):
    return depth_network(tuple(case["sensor_size"]), input={"refractory": 0, "t0": 0},
                         time_of_travel={"distance": case["distance"], "counter_bits": case["counter_bits"]},
                         depth={"min_depth": case["min_depth"], "max_depth": case["max_depth"]},
                         velocity={"source": "constant", "velocity": case["velocity"], "per": "pixel"})


def recording(case):
    return Recording(step_events(map(tuple, case["spikes"])), intrinsics=TEST_INTRINSICS)


@pytest.mark.parametrize("name", CASES)
def test_the_hand_values_follow_the_rules(name):
    case = CASES[name]
    tx, ty, _ = case["velocity"]
    seconds_per_count = 1e-3 / case["distance"]
    f, p = case["frac_bits"], case["payload_bits"]
    for d in case["depth"]:
        # A t = (-fx tx, -fy ty) with the principal point at 0, then W = quantize(A t * dt / distance)
        assert d["w_x"] == quantize(-200.0 * tx * seconds_per_count, f, p)
        assert d["w_y"] == quantize(-200.0 * ty * seconds_per_count, f, p)
        assert d["z_raw"] == fixed_depth(d["s_x"], d["s_y"], d["w_x"], d["w_y"], p)
        assert d["z"] == d["z_raw"] / 2**f
        if d["z_float"] is not None:
            assert abs(d["z"] - d["z_float"]) <= depth_tolerance(d["s_x"], d["s_y"], f) + 1e-12


@pytest.mark.parametrize("name", CASES)
def test_fixed_backend_reproduces_the_golden_case(name):
    case = CASES[name]
    result = FixedBackend(case["frac_bits"], case["payload_bits"]).run(network(case), recording(case),
                                                                       record_tot=True)
    tot = np.sort(result.tot, order=["step", "y", "x", "direction"])
    assert [list(r) for r in tot.tolist()] == sorted(case["tot"], key=lambda r: (r[0], r[2], r[1], r[3]))
    assert result.tot_spikes == len(case["tot"])
    expected = sorted(case["depth"], key=lambda d: (d["step"], d["y"], d["x"]))
    depth = np.sort(result.depth, order=["step", "y", "x"])
    assert depth[["step", "x", "y"]].tolist() == [(d["step"], d["x"], d["y"]) for d in expected]
    assert depth["t"].tolist() == [(d["step"] + 1) * 1000 for d in expected]
    assert depth["z"].tolist() == [d["z"] for d in expected]  # exact: z = Z_raw / 2**F
    assert result.rejected == {**case["rejected"], "rotation_dominated": 0}  # eq. 8: never rotation-dominated
    assert result.extra == {"frac_bits": case["frac_bits"], "payload_bits": case["payload_bits"]}


@pytest.mark.parametrize("name", CASES)
def test_the_kernel_reports_the_golden_z_raw(name):
    case = CASES[name]
    net = network(case)
    fmt = FixedPointFormat(case["frac_bits"], case["payload_bits"])
    camera = Recording(np.empty(0, EVENT_DTYPE), intrinsics=TEST_INTRINSICS)
    kernel = TimeOfTravelKernel(pipeline_of(net).kernel_config(camera, fmt))
    steps, xs, ys, ps = (np.array(c) for c in zip(*sorted(map(tuple, case["spikes"]))))
    out = kernel.process(steps, xs, ys, ps, np.tile(case["velocity"], (64, 1)), 0)
    assert sorted(zip(out.depth["x"].tolist(), out.z_raw.tolist())) == \
        sorted((d["x"], d["z_raw"]) for d in case["depth"])


@pytest.mark.parametrize("name", CASES)
def test_float_backend_on_the_golden_case(name):
    case = CASES[name]
    result = FloatBackend().run(network(case), recording(case))
    kept = [d for d in case["depth"] if d["z_float"] is not None]
    assert sorted(result.depth["z"].tolist()) == pytest.approx(sorted(d["z_float"] for d in kept), rel=1e-12)
    assert result.rejected == {**case.get("float_rejected", case["rejected"]), "rotation_dominated": 0}
