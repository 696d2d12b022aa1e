"""The time-surface estimator (tofnet.kernels.time_surface*) on synthetic edges with known depth."""

import math

import numpy as np
import pytest

from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, make_events
from tofnet.kernels import time_surface as ts
from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.time_surface_estimator import (QUALITY_DTYPE, TimeSurfaceConfig, TimeSurfaceEstimator,
                                                   constant_velocity)

F = 200.0
SENSOR = (32, 24)
INTRINSICS = (F, F, 15.5, 11.5)


def config(**changes):
    return TimeSurfaceConfig(SENSOR, INTRINSICS, **{"per_pixel": True, **changes})


def edge_events(direction, speed, depth, *, shape=lambda w: 0.0, polarity=1, start_us=1000, burst=1,
                burst_gap_us=200, sensor=SENSOR):
    """One straight or curved edge sweeping the sensor along unit ``direction`` at ``speed`` px/s.

    Pixel p fires when the edge passes it: ``t = (p·d + shape(p·d⊥)) / speed`` (``shape``
    bends the edge across the motion, in pixels), shifted so the first event is at
    ``start_us``; ``burst`` events per pixel ``burst_gap_us`` apart. Returns the events and
    the camera velocity (m/s) that moves a surface at ``depth`` m that way (lateral motion).
    """
    du, dv = direction
    ys, xs = np.mgrid[0:sensor[1], 0:sensor[0]]
    along, across = xs * du + ys * dv, ys * du - xs * dv
    t = (along + np.vectorize(shape)(across)) / speed
    t_us = np.round((t - t.min()) * 1e6).astype(np.int64) + start_us
    times = np.concatenate([t_us.ravel() + k * burst_gap_us for k in range(burst)])
    x = np.tile(xs.ravel(), burst)
    y = np.tile(ys.ravel(), burst)
    order = np.argsort(times, kind="stable")
    events = make_events(times[order], x[order], y[order], np.full(len(times), polarity))
    # image flow = -f t_xy / Z, so the camera moves against the flow
    velocity = (-du * speed * depth / F, -dv * speed * depth / F, 0.0)
    return events, velocity


def run(events, velocity, packets=None, record_rejected=False, **changes):
    estimator = TimeSurfaceEstimator(config(**changes), t0_us=0)
    rows = constant_velocity(velocity)
    if packets is None:
        depth, quality = estimator.feed(events, rows, record_rejected=record_rejected)
    else:
        parts = [estimator.feed(events[lo:hi], rows, record_rejected=record_rejected)
                 for lo, hi in zip(packets[:-1], packets[1:])]
        depth = np.concatenate([p[0] for p in parts])
        quality = np.concatenate([p[1] for p in parts])
    return depth, quality, estimator


@pytest.mark.parametrize("model", ts.MODELS)
@pytest.mark.parametrize("direction", [(1, 0), (-1, 0), (0, 1), (0, -1), (0.6, 0.8), (-0.8, 0.6)])
def test_a_straight_edge_gives_its_depth_exactly(model, direction):
    events, velocity = edge_events(direction, speed=50.0, depth=2.0)
    depth, quality, estimator = run(events, velocity, model=model)
    assert len(depth) > 100
    np.testing.assert_allclose(depth["z"], 2.0, rtol=1e-4)  # times are rounded to 1 µs
    assert np.all(quality["rms_px"] < 1e-3)


def test_a_curved_edge_gives_its_depth_exactly():
    events, velocity = edge_events((1, 0), speed=40.0, depth=1.5, shape=lambda w: 0.04 * w * w)
    depth, _, _ = run(events, velocity, model="rows", outlier_px=0.05)
    assert len(depth) > 100
    np.testing.assert_allclose(depth["z"], 1.5, rtol=1e-4)


def test_the_plane_model_is_bent_by_a_curved_edge():
    """A plane fitted across a curved edge picks up its curvature: one reason for the rows model."""
    events, velocity = edge_events((1, 0), speed=40.0, depth=1.5, shape=lambda w: 0.04 * w * w)
    depth, _, _ = run(events, velocity, model="plane", outlier_px=10.0, max_rms_px=10.0)
    assert np.max(np.abs(depth["z"] / 1.5 - 1)) > 0.01


def test_the_gradient_is_the_time_of_travel_with_the_design_sign():
    """docs/semantics.md (depth neuron): td = +count*dt/distance for motion towards +u, so ∇T_u > 0 for an edge moving to +u."""
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0)
    _, quality, _ = run(events, velocity, model="plane")
    np.testing.assert_allclose(quality["gx"], 1 / 50.0, rtol=1e-4)  # s/px
    np.testing.assert_allclose(quality["gy"], 0.0, atol=1e-7)
    events, velocity = edge_events((-1, 0), speed=50.0, depth=2.0)
    _, quality, _ = run(events, velocity, model="plane")
    np.testing.assert_allclose(quality["gx"], -1 / 50.0, rtol=1e-4)


def test_outliers_are_dropped_and_the_depth_stays_exact():
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0)
    late = (events["x"] % 5 == 2) & (events["y"] % 4 == 1)  # one pixel in 20 fires 6 ms (0.3 px) late
    events["t"][late] += 6000
    events = events[np.argsort(events["t"], kind="stable")]
    for model in ts.MODELS:
        depth, quality, _ = run(events, velocity, model=model, outlier_px=0.1, iterations=8)
        clean = ~np.isin(np.arange(len(events)), np.flatnonzero(late))[quality["index"]]
        assert clean.sum() > 100
        np.testing.assert_allclose(depth["z"][clean], 2.0, rtol=1e-3, err_msg=model)
        # without rejection the late pixels bend the fit
        depth0, quality0, _ = run(events, velocity, model=model, outlier_px=100.0, max_rms_px=100.0)
        clean0 = ~np.isin(np.arange(len(events)), np.flatnonzero(late))[quality0["index"]]
        assert np.max(np.abs(depth0["z"][clean0] / 2.0 - 1)) > 0.01, model


def test_every_event_is_counted_once_by_reason():
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0, burst=3)
    stray = make_events([events["t"][-1] + 1, events["t"][-1] + 2], [SENSOR[0], 3], [0, SENSOR[1] + 5], [1, 0])
    events = np.concatenate([events, stray])
    depth, _, estimator = run(events, velocity, burst_surfaces=1)
    counts = estimator.counts
    assert sum(counts.values()) == estimator.events_in == len(events)
    assert counts["out_of_bounds"] == 2
    assert counts["burst"] == 2 * SENSOR[0] * SENSOR[1]  # the hold keeps the 2nd and 3rd of each burst out
    assert counts["emitted"] == len(depth)
    assert estimator.first_events == SENSOR[0] * SENSOR[1]
    assert counts["too_few_points"] + counts["ill_conditioned"] > 0  # the first columns have nothing behind them


def test_events_before_t0_are_counted_not_used():
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0)
    t0 = int(events["t"][100])
    estimator = TimeSurfaceEstimator(config(), t0_us=t0)
    estimator.feed(events, constant_velocity(velocity))
    assert estimator.counts["before_t0"] == np.count_nonzero(events["t"] < t0) > 50


def test_output_is_stamped_like_every_depth_record():
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0, start_us=12_345)
    depth, quality, _ = run(events, velocity, latency_steps=2)
    assert depth.dtype == DEPTH_DTYPE and quality.dtype == QUALITY_DTYPE
    step = quality["t_event"] // 1000 + 2  # t0 = 0, 1 ms steps, latency 2
    np.testing.assert_array_equal(depth["step"], step)
    np.testing.assert_array_equal(depth["t"], (step + 1) * 1000)  # end of the output step
    np.testing.assert_array_equal(quality["t_event"], events["t"][quality["index"]])
    np.testing.assert_array_equal(depth["x"], events["x"][quality["index"]])
    assert np.all(quality["reason"] == ts.EMITTED)


def noisy_stream(seed=0):
    """Two edges of both polarities, bursts, jitter and noise: something for every code path."""
    rng = np.random.default_rng(seed)
    on, velocity = edge_events((0.8, 0.6), speed=60.0, depth=1.2, burst=3, start_us=0)
    off, _ = edge_events((0.8, 0.6), speed=60.0, depth=1.2, polarity=0, start_us=90_000)
    noise = make_events(rng.integers(0, 700_000, 500), rng.integers(0, SENSOR[0], 500),
                        rng.integers(0, SENSOR[1], 500), rng.integers(0, 2, 500))
    events = np.concatenate([on, off, noise])
    events["t"] += rng.integers(0, 3000, len(events))  # ~0.2 px of jitter
    return events[np.argsort(events["t"], kind="stable")], velocity


def test_the_output_does_not_depend_on_how_the_stream_is_split():
    events, velocity = noisy_stream()
    whole = run(events, velocity, record_rejected=True)
    rng = np.random.default_rng(1)
    cuts = np.unique(np.r_[0, np.sort(rng.integers(0, len(events), 40)), np.arange(0, 30), len(events)])
    split = run(events, velocity, packets=cuts, record_rejected=True)
    assert len(whole[0]) > 100
    assert whole[0].tobytes() == split[0].tobytes()  # rejected ones have z NaN: compare bits
    assert whole[1].tobytes() == split[1].tobytes()
    assert whole[2].counts == split[2].counts


def test_the_pinhole_shortcut_reads_what_the_sample_table_holds():
    # Per pixel without a lens the kernel computes A t at the pixel instead of reading the
    # lens sample table; the table's path must give the same bytes on a stream that turns.
    events, velocity = noisy_stream()

    def rows(first, count):  # the stream's velocity, drifting a little, with a z part: A t varies per pixel
        drift = 1.0 + 1e-4 * np.arange(first, first + count)[:, None]
        return np.array([velocity[0], velocity[1], 0.05]) * drift, first
    outputs = []
    for pinhole in (True, False):
        estimator = TimeSurfaceEstimator(config(), t0_us=0)
        assert estimator._ip[ts.I_PINHOLE] == 1
        estimator._ip[ts.I_PINHOLE] = int(pinhole)
        outputs.append((*estimator.feed(events, rows, record_rejected=True), estimator.counts))
    (d1, q1, c1), (d2, q2, c2) = outputs
    assert c1["emitted"] > 50
    assert d1.tobytes() == d2.tobytes() and q1.tobytes() == q2.tobytes() and c1 == c2


def test_a_packet_out_of_time_order_is_refused():
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0)
    estimator = TimeSurfaceEstimator(config(), t0_us=0)
    rows = constant_velocity(velocity)
    estimator.feed(events[:300], rows)
    with pytest.raises(BackendError, match="time order"):
        estimator.feed(events[:10], rows)


def test_velocity_rows_must_cover_the_packet():
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0)
    estimator = TimeSurfaceEstimator(config(), t0_us=0)
    with pytest.raises(BackendError, match="do not cover"):
        estimator.feed(events, lambda first, count: (np.tile(velocity, (1, 1)), first))


def test_same_polarity_fits_ignore_the_other_polarity():
    on, velocity = edge_events((1, 0), speed=50.0, depth=2.0)
    rng = np.random.default_rng(2)
    off = on.copy()
    off["p"] = 0
    off["t"] += rng.integers(-20_000, 20_000, len(off))  # an unrelated OFF surface over the same pixels
    off = off[off["t"] > 0]
    events = np.concatenate([on, off])
    events = events[np.argsort(events["t"], kind="stable")]
    depth, quality, _ = run(events, velocity)
    is_on = events["p"][quality["index"]] == 1
    assert is_on.sum() > 100
    np.testing.assert_allclose(depth["z"][is_on], 2.0, rtol=1e-4)


def test_the_hold_follows_the_measured_time_per_pixel():
    """A burst lasts hold_px pixels of the fitted time per pixel: 3 events 4 ms apart at 20 ms/px."""
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0, burst=3, burst_gap_us=4000)
    _, _, estimator = run(events, velocity, hold_px=1.0, refractory_depth=0.0)
    # before a fit measured a pixel, nothing holds its burst; after, 1 px = 20 ms does
    # (the first columns fit the bursts' later events too, before any hold: look further in)
    fitted = (estimator._hold[:, 1] > 0) & (np.arange(SENSOR[0] * SENSOR[1]) % SENSOR[0] >= 10)
    assert fitted.sum() > 100
    np.testing.assert_allclose(estimator._hold[fitted, 1], 20_001, atol=2)


def test_only_a_fit_close_to_its_points_sets_the_hold():
    """In noise a fit is far off its points: it measured no crossing time, so the hold stays as it was."""
    rng = np.random.default_rng(5)
    n = 200_000  # 260 events per pixel and second
    noise = make_events(np.sort(rng.integers(0, 1_000_000, n)), rng.integers(0, SENSOR[0], n),
                        rng.integers(0, SENSOR[1], n), rng.integers(0, 2, n))
    first = {}
    for rms in (1.0, math.inf):
        _, _, estimator = run(noise, (-0.5, 0.0, 0.0), hold_fit_rms_px=rms)
        first[rms] = estimator.first_events
        assert estimator.counts["bad_fit"] > 1000
    # noise fits' holds are short (a flat surface): they let most noise events through as first events
    assert first[1.0] < 0.5 * first[math.inf]
    events, velocity = edge_events((1, 0), speed=50.0, depth=2.0, burst=3, burst_gap_us=4000)
    _, _, clean = run(events, velocity, hold_px=1.0, refractory_depth=0.0, hold_fit_rms_px=0.0)
    assert (clean._hold > 0).sum() > 100  # exact fits (rms 0) of an ideal edge still set it


def test_a_first_event_with_nothing_behind_it_is_not_fitted():
    """behind_depth: an edge crossed the two pixels behind an event along the motion; noise did not."""
    rng = np.random.default_rng(5)
    n = 100_000
    noise = make_events(np.sort(rng.integers(0, 1_000_000, n)), rng.integers(0, SENSOR[0], n),
                        rng.integers(0, SENSOR[1], n), rng.integers(0, 2, n))
    fits = {}
    for behind in (0.0, 2.0):  # 2 m: the pixels behind must have fired within 20 ms per pixel
        _, _, estimator = run(noise, (-0.5, 0.0, 0.0), behind_depth=behind)
        fits[behind] = estimator.first_events - estimator.counts["nothing_behind"]
        assert (estimator.counts["nothing_behind"] > 0) == (behind > 0)
    assert fits[2.0] < 0.5 * fits[0.0]
    for direction in [(1, 0), (0, -1), (0.6, 0.8), (-0.8, 0.6)]:  # a clean edge keeps every estimate
        events, velocity = edge_events(direction, speed=50.0, depth=2.0)
        depth, _, estimator = run(events, velocity, behind_depth=10.0)
        depth0, _, _ = run(events, velocity, behind_depth=0.0)
        assert len(depth) > 100 and estimator.counts["nothing_behind"] > 0  # the first columns
        np.testing.assert_array_equal(depth, depth0)


def test_points_older_than_the_edges_own_pace_allows_are_not_used():
    """window_px: a pixel the present edge did not fire still holds an older edge's time; the
    two pixels behind measured the present edge's pace, and the window stops at window_px
    crossings of it (here 80 ms), before the older edge (100 ms back, within window_depth's 150)."""
    first, velocity = edge_events((1, 0), speed=50.0, depth=2.0)  # 20 ms per pixel
    second, _ = edge_events((1, 0), speed=50.0, depth=2.0, start_us=101_000)
    second = second[np.random.default_rng(3).random(len(second)) > 0.3]  # 30 % of its pixels stay silent
    events = np.concatenate([first, second])
    events = events[np.argsort(events["t"], kind="stable")]
    runs = {w: run(events, velocity, window_px=w, iterations=2) for w in (0.0, 4.0)}
    for depth, quality, _ in runs.values():
        np.testing.assert_allclose(depth["z"], 2.0, rtol=1e-4)
    paced, unbounded = runs[4.0][2].counts, runs[0.0][2].counts
    assert paced["bad_fit"] < 0.5 * unbounded["bad_fit"]  # the older edge's points pulled those fits off
    assert paced["emitted"] > unbounded["emitted"] + 50


def test_points_from_before_a_turn_are_not_used():
    """After the camera reverses, the old surface is another motion's: no estimate comes from it."""
    right, velocity = edge_events((1, 0), speed=50.0, depth=2.0, start_us=0)
    left, _ = edge_events((-1, 0), speed=50.0, depth=2.0, start_us=int(right["t"][-1]) + 5000, polarity=1)
    turn_us = int(left["t"][0]) - 2000
    events = np.concatenate([right, left])

    def rows(first, count):
        updates = np.arange(first, first + count)
        table = np.where((updates * 1000 < turn_us)[:, None], velocity, [-velocity[0], 0.0, 0.0])
        return table, first

    estimator = TimeSurfaceEstimator(config(hold_px=0.0, refractory_depth=0.0, refractory=0.001), t0_us=0)
    depth, quality = estimator.feed(events, rows)
    after = quality["t_event"] >= turn_us
    assert after.sum() > 100
    np.testing.assert_allclose(depth["z"][after], 2.0, rtol=1e-4)


def test_eq7_with_a_rotation_recovers_the_depth():
    """An edge moving with the flow A t / Z + B ω of one pixel: that pixel's estimate is Z (eq. 7)."""
    omega = (0.0, 0.05, 0.0)
    translation = (-0.2, 0.0, 0.0)
    z_true, x0, y0 = 1.6, 20, 12
    at = np.array([-F * translation[0], -F * translation[1]])
    bw = np.array(rotational_flow(*omega, float(x0), float(y0), F, F, *INTRINSICS[2:]))
    flow = at / z_true + bw
    speed = float(np.hypot(*flow))
    events, _ = edge_events(tuple(flow / speed), speed=speed, depth=1.0)
    estimator = TimeSurfaceEstimator(config(model="plane"), t0_us=0)
    depth, _ = estimator.feed(events, constant_velocity(translation, omega))
    at_pixel = (depth["x"] == x0) & (depth["y"] == y0)
    assert at_pixel.sum() == 1
    np.testing.assert_allclose(depth["z"][at_pixel], z_true, rtol=1e-4)


def test_a_bad_configuration_is_one_error_naming_the_fields():
    with pytest.raises(BackendError, match="model.*radius"):
        TimeSurfaceConfig(SENSOR, INTRINSICS, model="cubic", radius=0)
    with pytest.raises(BackendError, match="max_depth"):
        TimeSurfaceConfig(SENSOR, INTRINSICS, min_depth=5.0, max_depth=1.0)
    with pytest.raises(BackendError, match="max_turn: expected degrees from 1 to 180, got 0.5"):
        TimeSurfaceConfig(SENSOR, INTRINSICS, max_turn=0.5)
    with pytest.raises(BackendError, match="behind_depth: needs radius >= 2"):
        TimeSurfaceConfig(SENSOR, INTRINSICS, radius=1)
    with pytest.raises(BackendError, match="window_px: needs radius >= 2"):
        TimeSurfaceConfig(SENSOR, INTRINSICS, radius=1, behind_depth=0.0, window_px=6.0)
    with pytest.raises(BackendError, match="coordinates: travel needs radius >= 2"):
        TimeSurfaceConfig(SENSOR, INTRINSICS, radius=1, behind_depth=0.0, window_px=0.0)
    with pytest.raises(BackendError, match="coordinates: expected one of"):
        TimeSurfaceConfig(SENSOR, INTRINSICS, coordinates="space")
    TimeSurfaceConfig(SENSOR, INTRINSICS, radius=1, behind_depth=0.0, window_px=0.0, coordinates="time")


def test_what_is_emitted_does_not_depend_on_recording_the_rejections():
    # Without record_rejected the kernel stops early where nothing is to be recorded (nothing
    # behind, fewer points than min_points, a last pass over both rms limits); the estimates
    # and every count must be those of the run that records them all.
    events, velocity = noisy_stream()
    recorded = run(events, velocity, record_rejected=True)
    emitted_only = run(events, velocity)
    counts = recorded[2].counts
    assert min(counts["nothing_behind"], counts["too_few_points"], counts["bad_fit"], counts["emitted"]) > 0
    kept = recorded[1]["reason"] == ts.EMITTED
    assert recorded[0][kept].tobytes() == emitted_only[0].tobytes()
    assert recorded[1][kept].tobytes() == emitted_only[1].tobytes()
    assert emitted_only[2].counts == counts


def test_the_pixels_behind_are_the_rounded_unit_motion_found_from_squares():
    # the check behind rounds f and 2 f (f = a / |A t|) without a root: the same steps as floor(x + 0.5),
    # on random directions and on the exact ties (|f| = 1/4, 1/2, 3/4 of a power-of-two speed)
    behind = ts.behind_steps.py_func
    rng = np.random.default_rng(3)
    angles = np.concatenate([rng.uniform(0, 2 * np.pi, 4000), np.arccos([0.25, 0.5, 0.75, -0.25, -0.5, -0.75])])
    for angle in angles:
        a, b = 4.0 * math.cos(angle), 4.0 * math.sin(angle)
        speed2 = a * a + b * b
        for component in (a, b):
            f = component / math.sqrt(speed2)
            assert behind(component, speed2) == (math.floor(f + 0.5), math.floor(2 * f + 0.5)), (component, f)
    for f in (0.25, 0.5, 0.75, -0.25, -0.5, -0.75, 1.0, -1.0, 0.0):  # ties, exactly representable
        assert behind(f * 2.0, 4.0) == (math.floor(f + 0.5), math.floor(2 * f + 0.5)), f
