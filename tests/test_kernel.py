"""The event-driven kernel (tofnet.kernels.region) against docs/semantics.md, case by case."""

import numpy as np

from tofnet.backends.graph import canonical
import pytest

from tofnet.errors import BackendError
from tofnet.kernels.fixed_point import FixedPointFormat
from tofnet.kernels.kernel_config import DepthSettings, UnitSettings
from tofnet.kernels.region import KernelConfig, Region, TimeOfTravelKernel

PLUS_U, MINUS_U, PLUS_V, MINUS_V = range(4)
STEPS = 400  # velocity table rows the helpers provide


def config(sensor, *, distance=1, counter_bits=8, fixed=None, min_depth=0.05, max_depth=20.0, update_every=1,
           per_pixel=True, patch_size=30, intrinsics=(200.0, 200.0, 0.0, 0.0)):
    return KernelConfig(sensor_size=tuple(sensor), timestep_us=1000,
                        units=UnitSettings(distance=distance, counter_bits=counter_bits),
                        depth=DepthSettings(min_depth=min_depth, max_depth=max_depth, update_every=update_every,
                                            per_pixel=per_pixel, patch_size=patch_size, intrinsics=intrinsics),
                        fixed=fixed)


def arrays(spikes):
    """(step, x, y, p) tuples, kept in the given order, as the kernel's input arrays."""
    spikes = list(spikes)
    if not spikes:
        return tuple(np.empty(0, np.int64) for _ in range(4))
    return tuple(np.array(c, dtype=np.int64) for c in zip(*spikes))


def run(spikes, sensor=(2, 1), *, velocity=(-0.5, 0.0, 0.0), region=None, **kw):
    """Run hand-placed accepted spikes through one kernel: (depth, tot, kernel)."""
    kernel = TimeOfTravelKernel(config(sensor, **kw), region)
    table = np.tile(np.asarray(velocity, dtype=float), (STEPS, 1))
    out = kernel.process(*arrays(spikes), table, 0, record_tot=True)
    return out.depth, out.tot, kernel


def sent(tot, x, y, direction):
    sel = (tot["x"] == x) & (tot["y"] == y) & (tot["direction"] == direction)
    return list(zip(tot["step"][sel].tolist(), tot["count"][sel].tolist()))


def test_facilitation_in_step_a_and_trigger_in_step_b_send_b_minus_a():
    depth, tot, kernel = run([(3, 0, 0, 1), (8, 1, 0, 1)])
    assert sent(tot, 1, 0, PLUS_U) == [(9, 5)]  # the units run one step after the input
    assert kernel.tot_spikes == 1
    # depth neuron one step later: A t_x = -200 * -0.5 = 100 px m/s, Z = 100 * 5 * 1e-3
    assert depth[["step", "x", "y"]].tolist() == [(10, 1, 0)]
    assert depth["z"][0] == pytest.approx(0.5, rel=1e-15)
    assert depth["t"][0] == 11_000  # t0 = 0: end of step 10


def test_other_polarity_sends_nothing_and_the_counter_keeps_running():
    _, tot, _ = run([(3, 0, 0, 1), (8, 1, 0, 0), (12, 1, 0, 1)])
    assert sent(tot, 1, 0, PLUS_U) == [(13, 9)]


def test_trigger_before_facilitation_gives_nothing():
    _, tot, _ = run([(2, 1, 0, 1), (5, 0, 0, 1)])
    assert sent(tot, 1, 0, PLUS_U) == []
    assert sent(tot, 0, 0, MINUS_U) == [(6, 3)]  # pixel 1 facilitated the -u unit of pixel 0


@pytest.mark.parametrize("order", [1, -1])
def test_trigger_and_facilitation_in_one_step_use_the_older_state(order):
    same = [(4, 0, 0, 1), (4, 1, 0, 1)][::order]
    assert run(same)[2].tot_spikes == 0
    spikes = [(1, 0, 0, 1)] + [(6, 0, 0, 1), (6, 1, 0, 1)][::order] + [(9, 1, 0, 1)]
    _, tot, _ = run(spikes)
    assert sent(tot, 1, 0, PLUS_U) == [(7, 5), (10, 3)]  # step 6 uses step 1's facilitation, then restarts


@pytest.mark.parametrize("bits", [1, 3, 8, 30])
def test_overflow_at_exactly_the_counter_maximum(bits):
    top = 2**bits - 1
    # one velocity update for all steps, whatever their number
    _, at_max, _ = run([(0, 0, 0, 1), (top, 1, 0, 1)], counter_bits=bits, update_every=2**31)
    assert sent(at_max, 1, 0, PLUS_U) == [(top + 1, top)]
    _, past, _ = run([(0, 0, 0, 1), (top + 1, 1, 0, 1)], counter_bits=bits, update_every=2**31)
    assert sent(past, 1, 0, PLUS_U) == []


def test_refacilitation_restarts_and_sending_leaves_the_unit_idle():
    _, tot, _ = run([(1, 0, 0, 1), (4, 0, 0, 1), (10, 1, 0, 1)])
    assert sent(tot, 1, 0, PLUS_U) == [(11, 6)]
    _, tot, _ = run([(1, 0, 0, 1), (4, 1, 0, 1), (9, 1, 0, 1)])
    assert sent(tot, 1, 0, PLUS_U) == [(5, 3)]


def test_opposite_directions_keep_the_smaller_count_and_a_tie_measures_nothing():
    depth, tot, _ = run([(5, 2, 0, 1), (7, 0, 0, 1), (10, 1, 0, 1)], (3, 1))
    assert sorted(sent(tot, 1, 0, PLUS_U) + sent(tot, 1, 0, MINUS_U)) == [(11, 3), (11, 5)]
    assert depth["z"].tolist() == pytest.approx([100 * 3e-3])  # +u wins with count 3
    depth, tot, kernel = run([(6, 0, 0, 1), (6, 2, 0, 1), (10, 1, 0, 1)], (3, 1))
    assert len(tot) == 2 and len(depth) == 0
    assert kernel.rejected.tolist() == [1, 0, 0, 0]  # no_measurement


@pytest.mark.parametrize("facilitator,velocity", [
    ((0, 1), (-0.5, 0, 0)),  # edge moving +u: td_x = +5 ms, A t_x = +100
    ((2, 1), (+0.5, 0, 0)),  # -u: td_x = -5 ms, A t_x = -100
    ((1, 0), (0, -0.5, 0)),  # +v
    ((1, 2), (0, +0.5, 0)),  # -v
])
def test_sign_of_td_in_each_direction(facilitator, velocity):
    fx, fy = facilitator
    depth, tot, _ = run([(0, fx, fy, 1), (5, 1, 1, 1)], (3, 3), velocity=velocity)
    assert len(tot) == 1 and tot["count"][0] == 5
    assert depth["z"].tolist() == pytest.approx([0.5])


def test_distance_two():
    depth, tot, _ = run([(1, 0, 0, 1), (2, 1, 0, 1), (5, 2, 0, 1)], (3, 1), distance=2)
    assert sent(tot, 2, 0, PLUS_U) == [(6, 4)]
    assert depth["z"][depth["x"] == 2].tolist() == pytest.approx([100 * 4e-3 / 2])


def test_depth_outside_the_range_is_rejected_by_reason():
    assert run([(0, 0, 0, 1), (2, 1, 0, 1)], min_depth=0.5)[2].rejected.tolist() == [0, 1, 0, 0]
    assert run([(0, 0, 0, 1), (30, 1, 0, 1)], max_depth=2.0)[2].rejected.tolist() == [0, 0, 1, 0]
    assert run([(0, 0, 0, 1), (5, 1, 0, 1)], velocity=(0.5, 0, 0))[2].rejected.tolist() == [0, 1, 0, 0]


def test_velocity_update_held_by_the_depth_neuron():
    # update_every 4: the depth neuron in step s holds update (s-1)//4; spike at input step 9 -> s = 11 -> update 2
    kernel = TimeOfTravelKernel(config((2, 1), update_every=4))
    table = np.array([[-0.1, 0, 0], [-0.2, 0, 0], [-0.3, 0, 0], [-0.4, 0, 0]])
    out = kernel.process(*arrays([(3, 0, 0, 1), (9, 1, 0, 1)]), table, 0)
    assert out.depth["z"].tolist() == pytest.approx([200 * 0.3 * 6e-3])


def random_spikes(rng, sensor, n_steps, density):
    """Accepted-spike-like input: at most one spike per pixel and step, sorted by step."""
    width, height = sensor
    rows = []
    for k in range(n_steps):
        pixels = np.flatnonzero(rng.random(width * height) < density)
        rng.shuffle(pixels)
        rows += [(k, p % width, p // width, int(rng.integers(0, 2))) for p in pixels]
    return arrays(rows)


def canonical(depth):
    return np.sort(depth, order=["step", "y", "x"])


@pytest.mark.parametrize("distance", [1, 2, 6])  # 6: the halo is wider than a tile
def test_regions_tiling_the_sensor_equal_the_full_sensor(distance):
    rng = np.random.default_rng(distance)
    sensor = (23, 17)
    spikes = random_spikes(rng, sensor, 120, 0.08)
    table = np.tile([-0.3, 0.2, 0.4], (STEPS, 1))
    cfg = config(sensor, distance=distance, counter_bits=5, per_pixel=False, patch_size=6,
                 intrinsics=(200.0, 190.0, 11.0, 8.0))
    full = TimeOfTravelKernel(cfg).process(*spikes, table, 0, record_tot=True)
    depth, tot, rejected = [], [], np.zeros(4, np.int64)
    for y0 in range(0, 17, 5):
        for x0 in range(0, 23, 7):
            region = Region(x0, min(x0 + 7, 23), y0, min(y0 + 5, 17))
            kernel = TimeOfTravelKernel(cfg, region)
            keep = region.feeds(spikes[1], spikes[2], distance)
            out = kernel.process(*(a[keep] for a in spikes), table, 0, record_tot=True)
            depth.append(out.depth)
            tot.append(out.tot)
            rejected += kernel.rejected
    assert len(full.depth) > 100
    assert np.array_equal(canonical(np.concatenate(depth)), canonical(full.depth))
    order = ["step", "y", "x", "direction"]
    assert np.array_equal(np.sort(np.concatenate(tot), order=order), np.sort(full.tot, order=order))
    one = TimeOfTravelKernel(cfg)
    one.process(*spikes, table, 0)
    assert np.array_equal(rejected, one.rejected)


def test_a_region_ignores_spikes_it_does_not_need():
    rng = np.random.default_rng(5)
    sensor = (20, 20)
    spikes = random_spikes(rng, sensor, 60, 0.1)
    table = np.tile([-0.3, 0.2, 0.0], (STEPS, 1))
    region = Region(5, 12, 6, 15)
    cfg = config(sensor, distance=2)
    keep = region.feeds(spikes[1], spikes[2], 2)
    a = TimeOfTravelKernel(cfg, region).process(*spikes, table, 0, record_tot=True)
    b = TimeOfTravelKernel(cfg, region).process(*(s[keep] for s in spikes), table, 0, record_tot=True)
    assert np.array_equal(a.depth, b.depth) and np.array_equal(a.tot, b.tot) and len(a.tot) > 50


@pytest.mark.parametrize("fixed", [None, FixedPointFormat()])
def test_streaming_in_packets_equals_one_call(fixed):
    rng = np.random.default_rng(7)
    sensor = (16, 12)
    spikes = random_spikes(rng, sensor, 150, 0.1)
    table = np.tile([-0.3, 0.2, 0.4], (STEPS, 1))
    cfg = config(sensor, fixed=fixed, counter_bits=6)
    whole = TimeOfTravelKernel(cfg)
    one = whole.process(*spikes, table, 0, record_tot=True)
    streamed = TimeOfTravelKernel(cfg)
    cuts = np.sort(rng.choice(len(spikes[0]), 40, replace=False))  # many cut inside a step
    parts = [streamed.process(*(a[lo:hi] for a in spikes), table, 0, record_tot=True)
             for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(spikes[0])])]
    # each call is in pixel order within a step; a step split over calls is sorted once joined
    depth, z_raw = np.concatenate([p.depth for p in parts]), np.concatenate([p.z_raw for p in parts])
    order = np.lexsort((depth["x"], depth["y"], depth["step"]))
    assert np.array_equal(depth[order], one.depth) and np.array_equal(z_raw[order], one.z_raw)
    assert np.array_equal(canonical(np.concatenate([p.tot for p in parts])), canonical(one.tot))
    assert np.array_equal(streamed.rejected, whole.rejected) and streamed.tot_spikes == whole.tot_spikes


def test_rebasing_the_stamps_changes_nothing():
    rng = np.random.default_rng(11)
    sensor = (10, 8)
    spikes = random_spikes(rng, sensor, 300, 0.05)
    table = np.tile([-0.3, 0.2, 0.0], (STEPS, 1))
    cfg = config(sensor, counter_bits=4)
    plain = TimeOfTravelKernel(cfg).process(*spikes, table, 0, record_tot=True)
    kernel = TimeOfTravelKernel(cfg)
    kernel._rebase_after = 9  # rebase every few steps, with counters running across
    rebased = kernel.process(*spikes, table, 0, record_tot=True)
    assert np.array_equal(plain.tot, rebased.tot) and np.array_equal(plain.depth, rebased.depth)
    assert len(plain.tot) > 100


def test_unit_state_holds_the_step_and_polarity_of_the_last_facilitation():
    _, _, kernel = run([(3, 0, 0, 0), (7, 2, 0, 1)], (3, 1))
    step, polarity = kernel.unit_state()
    assert step[0, 1, PLUS_U] == 4 and polarity[0, 1, PLUS_U] == 0  # the units run one step after the input
    assert step[0, 1, MINUS_U] == -1  # step 7 is still buffered (it may continue in the next call)
    assert kernel.current_step == 7


def test_bad_input_is_refused():
    kernel = TimeOfTravelKernel(config((2, 1)))
    table = np.zeros((STEPS, 3))
    with pytest.raises(BackendError, match="not sorted"):
        kernel.process(*arrays([(5, 0, 0, 1), (3, 1, 0, 1)]), table, 0)
    kernel.process(*arrays([(5, 0, 0, 1)]), table, 0)  # the refused call left the state usable
    with pytest.raises(BackendError, match="not sorted"):
        kernel.process(*arrays([(4, 1, 0, 1)]), table, 0)
    with pytest.raises(BackendError, match="velocity table"):
        kernel.process(*arrays([(20, 1, 0, 1)]), table[:5], 0)
    with pytest.raises(BackendError, match="region"):
        TimeOfTravelKernel(config((2, 1)), Region(0, 3, 0, 1))
    with pytest.raises(BackendError, match="fixed-point range"):
        TimeOfTravelKernel(config((2, 1), fixed=FixedPointFormat(16, 24), max_depth=200.0))
