"""The fused kernel (input filter + time-of-travel units in one pass) equals the two stages run apart."""

import numpy as np

from tofnet.backends.graph import canonical
import pytest

from tofnet.errors import BackendError
from tofnet.events import make_events
from tofnet.kernels.depth import EMITTED, ROTATION_DOMINATED, classify, signed_axis_count
from tofnet.kernels.fixed_point import FixedPointFormat
from tofnet.kernels.input_filter import InputFilter
from tofnet.kernels.kernel_config import DepthSettings, InputFilterSettings, UnitSettings
from tofnet.kernels.region import KernelConfig, TimeOfTravelKernel
from tofnet.kernels.time_of_travel import N_REASONS, axis_count, outcome
from tofnet.models.depth import REJECT_REASONS

SENSOR = (19, 14)
T0 = 3_000


def config(*, refractory_us=2_500, per_polarity=False, distance=1, counter_bits=6, fixed=None, per_pixel=False,
           update_every=1):
    return KernelConfig(sensor_size=SENSOR, timestep_us=1000, units=UnitSettings(distance=distance,
                                                                                  counter_bits=counter_bits),
                        depth=DepthSettings(min_depth=0.05, max_depth=20.0, update_every=update_every,
                                            per_pixel=per_pixel, patch_size=5, intrinsics=(200.0, 190.0, 9.0, 6.5)),
                        input_filter=InputFilterSettings(refractory_us=refractory_us, per_polarity=per_polarity),
                        fixed=fixed)


def random_events(seed, n=12_000, duration_us=150_000):
    """Time-ordered events with bursts, repeats within a step, pixels outside the sensor and events before t0."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, duration_us, n))
    x = rng.integers(0, SENSOR[0] + 2, n)  # some outside
    y = rng.integers(0, SENSOR[1], n)
    x[1::7], y[1::7] = x[0::7][:len(x[1::7])], y[0::7][:len(y[1::7])]  # the same pixel again soon after
    return make_events(t, x, y, rng.integers(0, 2, n))


def table_rows(velocity):
    def rows(first, count):
        return np.tile(velocity, (first + count + 5, 1)), 0
    return rows


VELOCITY = np.array([-0.3, 0.2, 0.4])


def two_stage(cfg, events, record_tot=True):
    """The reference for the fused path: InputFilter, then the spike kernel, in one call each."""
    flt = InputFilter(cfg.sensor_size, T0, cfg.timestep_us, cfg.input_filter.refractory_us,
                      cfg.input_filter.per_polarity)
    kernel = TimeOfTravelKernel(cfg, t0_us=T0)
    steps, xs, ys, ps = flt.feed(events)
    out = kernel.process(steps, xs, ys, ps, *table_rows(VELOCITY)(0, int(steps[-1]) + 3),
                         record_tot=record_tot) if len(steps) else None
    return flt, kernel, out


def fused_in_packets(cfg, events, cuts):
    kernel = TimeOfTravelKernel(cfg, t0_us=T0)
    parts = [kernel.process_events(events[lo:hi], table_rows(VELOCITY), record_tot=True)
             for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(events)])]
    return kernel, parts


def assert_same(flt, two, out, fused, parts):
    # each call is in pixel order within a step; a step split over calls is sorted once joined
    depth, z_raw = np.concatenate([p.depth for p in parts]), np.concatenate([p.z_raw for p in parts])
    order = np.lexsort((depth["x"], depth["y"], depth["step"]))
    assert np.array_equal(depth[order], out.depth) and np.array_equal(z_raw[order], out.z_raw)
    assert np.array_equal(canonical(np.concatenate([p.tot for p in parts])), canonical(out.tot))
    assert fused.drops.tolist() == flt.drops.tolist() and fused.accepted == flt.accepted
    assert fused.rejected.tolist() == two.rejected.tolist() and fused.tot_spikes == two.tot_spikes
    assert fused.current_step == two.current_step
    for a, b in zip(fused.unit_state(), two.unit_state()):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("kw", [
    {},
    {"refractory_us": 0},
    {"refractory_us": 600},  # shorter than a step: same-step drops happen
    {"per_polarity": True, "refractory_us": 4_000},
    {"per_polarity": True, "refractory_us": 300},
    {"distance": 2, "fixed": FixedPointFormat(), "per_pixel": True},
    {"counter_bits": 3, "update_every": 3, "fixed": FixedPointFormat(12, 20)},
])
def test_fused_events_equal_the_filter_then_the_spike_kernel(kw):
    cfg = config(**kw)
    events = random_events(len(kw))
    flt, two, out = two_stage(cfg, events)
    assert len(out.depth) > 200 and flt.drops.sum() > 1000
    rng = np.random.default_rng(1)
    cuts = np.sort(rng.choice(len(events), 60, replace=False))
    cuts = np.r_[cuts[:30], cuts[30], cuts[30:]]  # an empty packet too
    fused, parts = fused_in_packets(cfg, events, cuts)
    assert_same(flt, two, out, fused, parts)


def test_events_out_of_time_order_are_refused_before_any_state_changes():
    cfg = config(refractory_us=0)
    events = random_events(3)
    lo = np.searchsorted(events["t"], 50_000)
    hi = np.searchsorted(events["t"], 50_999, side="right")
    events[lo:hi] = events[lo:hi][::-1]  # one step backwards: not in time order, steps still sorted
    kernel = TimeOfTravelKernel(cfg, t0_us=T0)
    with pytest.raises(BackendError, match="not sorted"):
        kernel.process_events(events, table_rows(VELOCITY))
    assert kernel.accepted == 0 and kernel.drops.sum() == 0 and kernel.current_step == -1


def test_events_going_back_a_step_are_refused():
    cfg = config(refractory_us=0)
    early = make_events([T0 + 1_100, T0 + 5_200], [1, 2], [1, 1], [1, 1])
    late = make_events([T0 + 9_000], [4], [1], [1])
    kernel = TimeOfTravelKernel(cfg, t0_us=T0)
    kernel.process_events(late, table_rows(VELOCITY))
    with pytest.raises(BackendError, match="not sorted"):
        kernel.process_events(early, table_rows(VELOCITY))
    assert kernel.accepted == 1 and kernel.current_step == 9  # the refused packet changed nothing


def test_velocity_rows_come_from_the_provider_however_the_events_are_spread():
    cfg = config(refractory_us=0, update_every=2)
    events = random_events(5, n=2_000)
    asked = []

    def rows(first, count):
        asked.append((first, count))
        return np.tile(VELOCITY, (count, 1)), first  # exactly what was asked for

    kernel = TimeOfTravelKernel(cfg, t0_us=T0)
    depth = kernel.process_events(events, rows).depth
    flt, _, out = two_stage(cfg, events)
    last_step = (int(events["t"][-1]) - T0) // 1000
    assert np.array_equal(depth, out.depth) and asked == [(0, (last_step + 1) // 2 + 1)]


def test_branchless_depth_rules_equal_the_depth_neuron():
    for mp in range(6):
        for mn in range(6):
            assert axis_count(mp, mn) == signed_axis_count(mp, mn)
    reasons = {}
    for fired in (0, 1):
        for measured in (False, True):
            for z in (-1.0, 0.05, 0.06, 19.9, 20.0, 25.0):
                slot = outcome(fired, measured, z, 0.05, 20.0)
                # slots: REJECT_REASONS indices, then emitted, then no unit fired
                expected = N_REASONS + 1 if not fired else (N_REASONS if classify(measured, z, 0.05, 20.0) == EMITTED
                                                            else classify(measured, z, 0.05, 20.0))
                assert slot == expected
                reasons[slot] = True
            assert outcome(fired, measured, 3277, 3277, 1310720) == (1 if fired and measured else 0 if fired
                                                                     else N_REASONS + 1)
    # every eq. 8 outcome; never rotation_dominated (slot 3), which only eq. 7 gives
    assert sorted(reasons) == [0, 1, 2, N_REASONS, N_REASONS + 1]
    assert N_REASONS == len(REJECT_REASONS) and REJECT_REASONS[ROTATION_DOMINATED] == "rotation_dominated"


def test_a_region_filters_its_halo_and_counts_and_emits_only_its_own_pixels():
    """A band's kernel (tofnet.backends.bands) given every event: its pixels' estimates are the
    whole sensor's, its halo's events are filtered but not counted, events beyond it skipped."""
    from tofnet.kernels.region import Region

    events = random_events(0)
    whole = TimeOfTravelKernel(config())
    full = whole.process_events(events, table_rows(VELOCITY))
    region = Region(0, SENSOR[0], 3, 9)
    band = TimeOfTravelKernel(config(), region)
    part = band.process_events(events, table_rows(VELOCITY))
    inside = (full.depth["y"] >= 3) & (full.depth["y"] < 9)
    assert inside.sum() > 20 and part.depth.tobytes() == full.depth[inside].tobytes()
    rows = (events["y"] >= 3) & (events["y"] < 9)
    own = rows & (events["x"] < SENSOR[0])
    # out of bounds: counted by the band of the event's row, or every band for rows past the sensor
    # (only the first band is given those: kernels.bands.select_rows)
    outside = (rows & (events["x"] >= SENSOR[0])) | (events["y"] >= SENSOR[1])
    alone = TimeOfTravelKernel(config())
    alone.process_events(events[own | outside], table_rows(VELOCITY))  # the filter is per pixel
    assert band.accepted == alone.accepted and np.array_equal(band.drops, alone.drops)


