"""docs/semantics.md, one case at a time, on every registered backend."""

import numpy as np
import pytest

import contextlib

from tofnet.backends.registry import available_backends, get_backend
from tofnet.conformance import BackendRunner
from tofnet.events import DIRECTIONS, make_events
from tofnet.io.recording import Recording
from tofnet.kernels.fixed_point import depth_tolerance
from tofnet.networks import depth_network
from tofnet.testing import TEST_INTRINSICS, moving_edge, run_network, run_steps

PLUS_U, MINUS_U, PLUS_V, MINUS_V = range(4)


def spikes_of(result, x, y, direction):
    tot = result.tot
    sel = (tot["x"] == x) & (tot["y"] == y) & (tot["direction"] == direction)
    return list(zip(tot["step"][sel].tolist(), tot["count"][sel].tolist()))


@pytest.fixture(scope="module", params=available_backends())
def backend(request):
    """Every registered backend, through one session per module (multiproc spawns once)."""
    with contextlib.ExitStack() as stack:
        yield BackendRunner(get_backend(request.param), stack)


def approx_depth(expected, backend, *counts):
    """``expected`` metres within the backend's arithmetic: exact for float, the documented
    quantisation bound (docs/fixed_point.md) for fixed point; ``counts`` are m_x, m_y."""
    if backend.arithmetic == "fixed":
        return pytest.approx(expected, rel=0, abs=float(depth_tolerance(*counts)))
    return pytest.approx(expected, rel=1e-12)


def test_facilitation_then_trigger_sends_the_step_difference(backend):
    result = run_steps([(3, 0, 0, 1), (8, 1, 0, 1)], (2, 1), backend=backend)
    # trigger event in input step 8 reaches the unit in step 9
    assert spikes_of(result, 1, 0, PLUS_U) == [(9, 5)]
    assert result.tot_spikes == 1


def test_trigger_of_other_polarity_sends_nothing_and_counter_keeps_running(backend):
    result = run_steps([(3, 0, 0, 1), (8, 1, 0, 0), (12, 1, 0, 1)], (2, 1), backend=backend)
    assert spikes_of(result, 1, 0, PLUS_U) == [(13, 9)]


def test_trigger_before_facilitation_gives_nothing_in_that_direction(backend):
    result = run_steps([(2, 1, 0, 1), (5, 0, 0, 1)], (2, 1), backend=backend)
    assert spikes_of(result, 1, 0, PLUS_U) == []
    # the edge moved towards -u: pixel 1 facilitated the -u unit of pixel 0
    assert spikes_of(result, 0, 0, MINUS_U) == [(6, 3)]


def test_trigger_and_facilitation_in_the_same_step(backend):
    # no earlier facilitation: nothing
    assert run_steps([(4, 0, 0, 1), (4, 1, 0, 1)], (2, 1), backend=backend).tot_spikes == 0
    # earlier facilitation in step 1: the trigger in step 6 uses it (5), then step 6 re-facilitates
    result = run_steps([(1, 0, 0, 1), (6, 0, 0, 1), (6, 1, 0, 1), (9, 1, 0, 1)], (2, 1), backend=backend)
    assert spikes_of(result, 1, 0, PLUS_U) == [(7, 5), (10, 3)]


@pytest.mark.parametrize("bits", [3, 8])
def test_overflow_at_the_counter_maximum(backend, bits):
    top = 2**bits - 1
    at_max = run_steps([(0, 0, 0, 1), (top, 1, 0, 1)], (2, 1), backend=backend, counter_bits=bits)
    assert spikes_of(at_max, 1, 0, PLUS_U) == [(top + 1, top)]
    past = run_steps([(0, 0, 0, 1), (top + 1, 1, 0, 1)], (2, 1), backend=backend, counter_bits=bits)
    assert spikes_of(past, 1, 0, PLUS_U) == []


def test_refacilitation_restarts_the_counter(backend):
    result = run_steps([(1, 0, 0, 1), (4, 0, 0, 1), (10, 1, 0, 1)], (2, 1), backend=backend)
    assert spikes_of(result, 1, 0, PLUS_U) == [(11, 6)]


def test_after_sending_the_unit_is_idle_until_facilitated_again(backend):
    result = run_steps([(1, 0, 0, 1), (4, 1, 0, 1), (9, 1, 0, 1)], (2, 1), backend=backend)
    assert spikes_of(result, 1, 0, PLUS_U) == [(5, 3)]


def test_distance_two_facilitates_from_two_pixels_back(backend):
    result = run_steps([(1, 0, 0, 1), (2, 1, 0, 1), (5, 2, 0, 1)], (3, 1), backend=backend, distance=2)
    assert spikes_of(result, 2, 0, PLUS_U) == [(6, 4)]
    # depth uses td = m * dt / distance: A t_x = -200 * -0.5 = 100 px m/s -> Z = 100 * 4e-3 / 2
    assert result.depth["z"][result.depth["x"] == 2] == approx_depth([0.2], backend, 4, 0)


def test_opposite_directions_keep_the_smaller_count(backend):
    # pixel 1 triggered at step 10; +u facilitated at 7 (count 3), -u at 5 (count 5)
    result = run_steps([(5, 2, 0, 1), (7, 0, 0, 1), (10, 1, 0, 1)], (3, 1), backend=backend)
    assert sorted(spikes_of(result, 1, 0, PLUS_U) + spikes_of(result, 1, 0, MINUS_U)) == [(11, 3), (11, 5)]
    z = result.depth["z"][result.depth["x"] == 1]
    assert z == approx_depth([100 * 3e-3], backend, 3, 0)  # +u wins: positive td with count 3


def test_a_tie_between_opposite_directions_measures_nothing(backend):
    result = run_steps([(6, 0, 0, 1), (6, 2, 0, 1), (10, 1, 0, 1)], (3, 1), backend=backend)
    assert len(spikes_of(result, 1, 0, PLUS_U)) == 1 and len(spikes_of(result, 1, 0, MINUS_U)) == 1
    assert not np.any(result.depth["x"] == 1)
    assert result.rejected["no_measurement"] == 1


@pytest.mark.parametrize("axis,speed,velocity", [
    ("u", +50.0, (-0.25, 0, 0)),   # scene moves +u when the camera moves -x
    ("u", -50.0, (+0.25, 0, 0)),
    ("v", +50.0, (0, -0.25, 0)),
    ("v", -50.0, (0, +0.25, 0)),
])
def test_sign_of_td_in_each_direction_gives_a_positive_depth(backend, axis, speed, velocity):
    # |flow| = f |t| / Z = 200 * 0.25 / 1 = 50 px/s -> Z = 1 m
    sensor = (12, 12)
    events = moving_edge(sensor, speed, axis)
    net = depth_network(sensor, input={"refractory": 0},
                        velocity={"source": "constant", "velocity": list(velocity), "per": "pixel"})
    result = run_network(net, Recording(events, intrinsics=TEST_INTRINSICS), backend=backend)
    assert len(result.depth) == 11 * 12
    assert result.depth["z"] == approx_depth(1.0, backend, 20, 0)


def test_depth_outside_the_range_is_rejected_and_counted(backend):
    near = run_steps([(0, 0, 0, 1), (2, 1, 0, 1)], (2, 1), backend=backend, min_depth=0.5)  # Z = 0.2
    assert len(near.depth) == 0 and near.rejected["too_near"] == 1
    far = run_steps([(0, 0, 0, 1), (30, 1, 0, 1)], (2, 1), backend=backend, max_depth=2.0)  # Z = 3
    assert len(far.depth) == 0 and far.rejected["too_far"] == 1
    wrong_way = run_steps([(0, 0, 0, 1), (5, 1, 0, 1)], (2, 1), backend=backend, velocity=(0.5, 0, 0))
    assert len(wrong_way.depth) == 0 and wrong_way.rejected["too_near"] == 1  # negative depth


def test_depth_is_stamped_at_the_end_of_its_step_two_steps_after_the_event(backend):
    result = run_steps([(3, 0, 0, 1), (8, 1, 0, 1)], (2, 1), backend=backend)
    (estimate,) = result.depth
    assert estimate["step"] == 10 and estimate["t"] == 11_000
    assert result.latency_steps == 2


def test_every_input_event_is_accounted_for(backend):
    # out of bounds, same step, refractory
    net = depth_network((4, 1), input={"refractory": "3ms", "t0": 0},
                        velocity={"source": "constant", "velocity": [-0.5, 0, 0]})
    events = make_events([100, 200, 300, 1500, 3200, 3300, 5000], [0, 0, 9, 0, 0, 1, 0], [0] * 7, [1] * 7)
    result = run_network(net, Recording(events, intrinsics=TEST_INTRINSICS), backend=backend)
    assert result.dropped == {"out_of_bounds": 1, "before_t0": 0, "refractory": 3, "same_step": 0}
    assert result.accepted == 3 and result.events_in == 7


def test_same_step_drop_when_refractory_is_shorter_than_a_step(backend):
    net = depth_network((4, 1), input={"refractory": "100us", "t0": 0},
                        velocity={"source": "constant", "velocity": [-0.5, 0, 0]})
    events = make_events([100, 150, 400, 900, 1000], [0] * 5, [0] * 5, [1, 1, 0, 1, 1])
    result = run_network(net, Recording(events, intrinsics=TEST_INTRINSICS), backend=backend)
    assert result.dropped["refractory"] == 1 and result.dropped["same_step"] == 2
    assert result.accepted == 2


def test_direction_names_follow_the_channel_order():
    assert DIRECTIONS == ("+u", "-u", "+v", "-v")
