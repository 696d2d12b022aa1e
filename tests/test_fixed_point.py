"""Fixed-point formats, the precision claim and the fixed-vs-float tolerance of docs/fixed_point.md."""

import numpy as np
import pytest

from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.errors import BackendError
from tofnet.events import make_events
from tofnet.io.recording import Intrinsics, Recording
from tofnet.kernels.depth import float_depth, signed_axis_count
from tofnet.kernels.fixed_point import (FixedPointFormat, depth_tolerance, fixed_depth, quantize,
                                        relative_error_bound, round_half_away, saturate)
from tofnet.networks import depth_network
from tofnet.testing import TEST_INTRINSICS, moving_edge


def test_rounding_and_saturation_rules():
    assert [round_half_away(v) for v in (2.5, -2.5, 2.4999, -2.4999, 0.0, -0.0, 7.0)] == [3, -3, 2, -2, 0, 0, 7]
    assert [saturate(v, 4) for v in (7, 8, -8, -9, 0)] == [7, 7, -8, -8, 0]
    assert quantize(float("nan"), 16, 24) == 0
    assert quantize(float("-inf"), 16, 24) == -(2**23)


def test_format_limits_and_validation():
    fmt = FixedPointFormat()
    assert (fmt.frac_bits, fmt.payload_bits) == (16, 24)
    assert fmt.max_raw == 2**23 - 1 and fmt.min_raw == -(2**23)
    assert fmt.max_value == pytest.approx(128.0, abs=2**-16) and fmt.lsb == 2**-16
    assert fmt.quantize(20.0) == 20 * 65536 and fmt.to_float(32770) == 32770 / 65536
    for frac_bits, payload_bits in ((24, 24), (-1, 24), (8, 1), (8, 33)):
        with pytest.raises(BackendError):
            FixedPointFormat(frac_bits, payload_bits)
    with pytest.raises(BackendError):
        FixedBackend(frac_bits=30, payload_bits=24)


def test_depth_tolerance_works_on_arrays():
    assert depth_tolerance(np.array([5, -3]), np.array([0, 2]), 16).tolist() == [5 * 2**-17, 5 * 2**-17]


@pytest.mark.parametrize("speed", [0.55, 2.6])
@pytest.mark.parametrize("distance", [1, 2])
def test_quantisation_changes_depth_by_less_than_a_thousandth_at_the_papers_speeds(speed, distance):
    # Lateral motion, f = 200 px, dt = 1 ms: one axis measured, Z = m W for every count m.
    at = 200.0 * speed
    seconds_per_count = 1e-3 / distance
    w = quantize(at * seconds_per_count, 16, 24)
    bound = relative_error_bound(at, 1e-3, distance, 16)
    assert bound < 1e-3
    for z_true in np.linspace(0.1, 20.0, 300):
        m = max(1, round(z_true / (at * seconds_per_count)))
        for sign in (1, -1):  # both directions of motion
            z_float = float_depth(sign * m, 0, sign * at, 0.0, seconds_per_count)
            z_fixed = fixed_depth(sign * m, 0, sign * w, 0, 24) * 2**-16
            assert abs(z_fixed - z_float) <= bound * z_float * (1 + 1e-9)


def test_fixed_backend_on_a_slow_moving_edge_is_within_a_thousandth_of_float():
    # 0.55 m/s at 1 m with f = 200: 110 px/s, counts of 9 steps; distance 2
    net = depth_network((20, 6), input={"refractory": 0},
                        time_of_travel={"distance": 2},
                        velocity={"source": "constant", "velocity": [-0.55, 0, 0], "per": "pixel"})
    recording = Recording(moving_edge((20, 6), 110.0), intrinsics=TEST_INTRINSICS)
    fixed, flt = FixedBackend().run(net, recording), FloatBackend().run(net, recording)
    assert len(fixed.depth) == len(flt.depth) > 50
    assert np.max(np.abs(fixed.depth["z"] / flt.depth["z"] - 1)) < 1e-3


def signed_counts(result):
    """(s_x, s_y) of every estimate, read off the time-of-travel spikes one step earlier."""
    tot = result.tot
    counts = {}
    for step, x, y, direction, count in tot.tolist():
        counts.setdefault((step + 1, x, y), [0, 0, 0, 0])[direction] = count
    m = np.array([counts[(s, x, y)] for s, x, y in result.depth[["step", "x", "y"]].tolist()]).reshape(-1, 4)
    sx = np.array([signed_axis_count(a, b) for a, b in m[:, :2]])
    sy = np.array([signed_axis_count(a, b) for a, b in m[:, 2:]])
    return sx, sy


def test_fixed_and_float_backends_agree_within_the_documented_tolerance():
    rng = np.random.default_rng(3)
    sensor, n = (48, 36), 80_000
    t = np.sort(rng.integers(0, 400_000, n))
    events = make_events(t, rng.integers(0, 48, n), rng.integers(0, 36, n), rng.integers(0, 2, n))
    net = depth_network(sensor, input={"refractory": "1ms"}, depth={"min_depth": 0.2, "max_depth": 3.0},
                        velocity={"source": "constant", "velocity": [-0.6, 0.3, 0.5], "patch_size": 10})
    recording = Recording(events, intrinsics=Intrinsics(200.0, 200.0, 23.5, 17.5))
    frac_bits = 8  # coarse, so that some estimates straddle the thresholds
    fixed = FixedBackend(frac_bits=frac_bits).run(net, recording, record_tot=True)
    flt = FloatBackend().run(net, recording, record_tot=True)
    assert np.array_equal(fixed.tot, flt.tot)  # counters are exact integers in both
    assert fixed.rejected["no_measurement"] == flt.rejected["no_measurement"]

    def keyed(result):
        sx, sy = signed_counts(result)
        tol = depth_tolerance(sx, sy, frac_bits) + 1e-12 * np.abs(result.depth["z"])
        return {key: (z, e) for key, z, e in zip(result.depth[["t", "x", "y", "step"]].tolist(),
                                                 result.depth["z"].tolist(), tol.tolist())}

    a, b = keyed(fixed), keyed(flt)
    both = a.keys() & b.keys()
    assert len(both) > 1000
    assert all(abs(a[k][0] - b[k][0]) <= a[k][1] for k in both)
    # Estimates only one backend kept lie within the tolerance of a threshold.
    for only, other in ((a.keys() - b.keys(), a), (b.keys() - a.keys(), b)):
        for k in only:
            z, tol = other[k]
            assert min(abs(z - 0.2), abs(z - 3.0)) <= 2 * tol
    assert len(a.keys() ^ b.keys()) < 0.05 * len(both)
    moved = len(a.keys() - b.keys()) - len(b.keys() - a.keys())
    assert sum(flt.rejected.values()) - sum(fixed.rejected.values()) == moved
