"""The time-surface fit in travel coordinates: exact depths when the camera's speed changes."""

import numpy as np
import pytest

from tofnet.events import make_events
from tofnet.kernels import time_surface_travel as tt
from tofnet.kernels.rotation import rotational_flow
from tofnet.kernels.time_surface_estimator import TimeSurfaceConfig, TimeSurfaceEstimator

F = 200.0
SENSOR = (32, 24)
INTRINSICS = (F, F, 15.5, 11.5)
DEPTH = 2.0


def speeds(n_steps):
    """Image speed px/s per 1 ms step: changing every step, between 20 and 80 px/s."""
    k = np.arange(n_steps)
    return 50.0 + 30.0 * np.sin(0.37 * k) * np.cos(0.11 * k)


def varying_edge(direction=(1.0, 0.0), n_steps=2000):
    """A straight edge sweeping the sensor along ``direction`` at ``speeds`` (px/s per 1 ms step) and the
    velocity rows (one per step) that move a surface at ``DEPTH`` that way."""
    du, dv = direction
    s = speeds(n_steps)
    reached = np.concatenate([[0.0], np.cumsum(s) * 1e-3])  # px travelled at each step's start
    ys, xs = np.mgrid[0:SENSOR[1], 0:SENSOR[0]]
    along = (xs * du + ys * dv).ravel()
    along = along - along.min() + 0.5
    k = np.searchsorted(reached, along, side="right") - 1
    t = np.round((k + (along - reached[k]) / (s[k] * 1e-3)) * 1000.0).astype(np.int64) + 1000  # µs
    # an OFF event at pixel (0, 0) every step, as a sensor's noise makes: the velocity of a step without events
    # is taken as the last one's (docs/time_surface.md, section 7)
    filler = np.arange(1000, int(t.max()) + 1000, 1000)
    t_all = np.concatenate([t, filler])
    x_all = np.concatenate([xs.ravel(), np.zeros(len(filler), np.int64)])
    y_all = np.concatenate([ys.ravel(), np.zeros(len(filler), np.int64)])
    p_all = np.concatenate([np.ones(len(t), np.int64), np.zeros(len(filler), np.int64)])
    order = np.argsort(t_all, kind="stable")
    events = make_events(t_all[order], x_all[order], y_all[order], p_all[order])
    velocity = np.column_stack([-du * s * DEPTH / F, -dv * s * DEPTH / F, np.zeros(n_steps)])
    velocity = np.concatenate([velocity[:1], velocity])  # the edge starts in input step 1 (1000 µs), held by update 1

    def rows(first, count):
        return velocity[np.clip(np.arange(first, first + count), 0, len(velocity) - 1)], first

    return events, rows


def run(events, rows, packets=None, **changes):
    estimator = TimeSurfaceEstimator(TimeSurfaceConfig(SENSOR, INTRINSICS, per_pixel=True, **changes), t0_us=0)
    cuts = [0, len(events)] if packets is None else packets
    parts = [estimator.feed(events[lo:hi], rows) for lo, hi in zip(cuts[:-1], cuts[1:])]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]), estimator


@pytest.mark.parametrize("direction", [(1.0, 0.0), (0.0, -1.0), (0.6, 0.8)])
def test_travel_gives_the_depth_exactly_while_the_speed_changes(direction):
    events, rows = varying_edge(direction)
    depth, quality, estimator = run(events, rows, coordinates="travel", turn=0.0)
    assert len(depth) > 100
    np.testing.assert_allclose(depth["z"], DEPTH, rtol=2e-3)  # times are rounded to 1 µs


def test_time_coordinates_are_bent_by_the_same_speed_changes():
    events, rows = varying_edge()
    travel, _, _ = run(events, rows, coordinates="travel", turn=0.0)
    time, _, _ = run(events, rows, coordinates="time", turn=0.0, max_rms_px=10.0)
    assert np.median(np.abs(time["z"] / DEPTH - 1)) > 20 * np.median(np.abs(travel["z"] / DEPTH - 1))


def test_travel_output_does_not_depend_on_the_packets():
    events, rows = varying_edge()
    whole, q_whole, est = run(events, rows, coordinates="travel")
    cuts = [0, 7, 100, 101, 350, len(events) // 2, len(events)]
    split, q_split, est_split = run(events, rows, packets=cuts, coordinates="travel")
    assert whole.tobytes() == split.tobytes() and q_whole.tobytes() == q_split.tobytes()
    assert est.counts == est_split.counts


def test_the_ring_holds_the_displacement_and_fills_steps_without_events():
    ring, state = np.zeros((tt.RING, tt.N_R)), np.full(tt.N_S, tt.NOT_YET, np.int64)
    tt.advance(ring, state, 5, np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.5]), 1e-3)
    tt.advance(ring, state, 9, np.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.5]), 1e-3)  # steps 6-8 had no events
    assert list(state) == [9, 5, 9]

    def at(t):
        return tt.travel_at(ring, t, 0, 1000, 1e-3, 1.0, 0.0, 0.0, 0.0, 0.0, 2.0)

    assert at(5000) == pytest.approx((0.0, 0.0))
    assert at(9000) == pytest.approx((4e-3, 4e-3))  # 4 ms at 1 m/s (the last velocity), and 0.5 rad/s
    assert at(9500) == pytest.approx((5e-3, 4.5e-3))  # then 0.5 ms at 2 m/s
    tt.advance(ring, state, 10, np.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.5]), 1e-3)
    assert state[tt.S_CHANGE] == 9  # the same velocity: no change
    tt.advance(ring, state, 11, np.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.6]), 1e-3)
    assert state[tt.S_CHANGE] == 11  # the angular velocity changed


def turning_edge(n_steps=1500, sub=20):
    """A vertical edge moved along +u by a constant translation (50 px/s at ``DEPTH``) and a rotation
    about y whose image speed changes every step (up to ±20 px/s at the centre), integrated in
    ``sub`` parts per 1 ms step; and its velocity rows (six columns)."""
    k = np.arange(n_steps)
    wy = 20.0 / F * np.sin(0.21 * k) * np.sign(np.cos(0.05 * k))  # rad/s: -(F + x²/F) wy px/s along u
    tx = -50.0 * DEPTH / F
    cx = INTRINSICS[2]
    position, crossed = -0.5, {}
    for step in range(n_steps):
        for part in range(sub):
            speed = -F * tx / DEPTH - (F + (position - cx) ** 2 / F) * wy[step]
            position += speed * 1e-3 / sub
            column = int(np.floor(position))
            if 0 <= column < SENSOR[0] and column not in crossed:
                crossed[column] = 1000 + step * 1000 + (part + 1) * 1000 // sub
    velocity = np.column_stack([np.full(n_steps, tx), np.zeros(n_steps), np.zeros(n_steps), np.zeros(n_steps), wy,
                                np.zeros(n_steps)])
    return columns_crossing(list(crossed), list(crossed.values()), velocity)


def columns_crossing(columns, times_us, velocity):
    """ON events of whole pixel columns at their times (µs), an OFF event at pixel (0, 0) every step as a
    sensor's noise makes, and the velocity rows (one per 1 ms step; the first held by update 1)."""
    t = np.repeat(np.asarray(times_us, np.int64), SENSOR[1])
    x = np.repeat(np.asarray(columns, np.int64), SENSOR[1])
    y = np.tile(np.arange(SENSOR[1]), len(columns))
    filler = np.arange(1000, int(t.max()) + 1000, 1000)
    t_all = np.concatenate([t, filler])
    order = np.argsort(t_all, kind="stable")
    events = make_events(t_all[order], np.concatenate([x, np.zeros(len(filler), np.int64)])[order],
                         np.concatenate([y, np.zeros(len(filler), np.int64)])[order],
                         np.concatenate([np.ones(len(t), np.int64), np.zeros(len(filler), np.int64)])[order])
    velocity = np.concatenate([velocity[:1], velocity])

    def rows(first, count):
        return velocity[np.clip(np.arange(first, first + count), 0, len(velocity) - 1)], first

    return events, rows


def test_travel_takes_the_rotation_out_while_it_changes():
    events, rows = turning_edge()
    travel, _, estimator = run(events, rows, coordinates="travel")
    time, _, _ = run(events, rows, coordinates="time", turn=0.0, max_rms_px=10.0)
    assert len(travel) > 100
    error = np.abs(travel["z"] / DEPTH - 1)
    assert np.median(error) < 2e-3 and np.percentile(error, 90) < 5e-3  # B ω at the event for the whole square
    assert np.median(np.abs(time["z"] / DEPTH - 1)) > 50 * np.median(error)  # eq. 7 with the present ω only


def forward_edge(speed_of_step, n_steps=800, x0=0.02, z0=1.0, cy=11.0):
    """A vertical edge at x0 m on a plane z0 m away, the camera moving along its optical axis at
    ``speed_of_step(k)`` m/s in step k (1 ms): the image moves away from the principal point and speeds up
    as it goes (``(1 + e s)²``, docs/time_surface.md 7g). Pixel columns fire ON when the edge reaches
    them; returns the events, the velocity rows, the intrinsics and the true depth (m) at a time (µs)."""
    intrinsics = (F, F, 15.5, cy)
    tz = np.array([speed_of_step(k) for k in range(n_steps)])
    pz = np.concatenate([[0.0], np.cumsum(tz) * 1e-3])  # at each step's start (input step k + 1 starts at k ms)
    xs, ts = [], []
    for column in range(SENSOR[0]):
        offset = column - intrinsics[2]
        if offset <= 0:
            continue
        needed = z0 - F * x0 / offset  # the travel at which the edge reaches the column
        k = np.searchsorted(pz, needed, side="right") - 1
        if 0 <= needed and k < n_steps:
            xs.append(column)
            ts.append(int(round(1000 + (k + (needed - pz[k]) / (tz[k] * 1e-3)) * 1000)))
    events, rows = columns_crossing(xs, ts, np.column_stack([np.zeros(n_steps), np.zeros(n_steps), tz]))

    def true_depth(t_us):
        k = np.clip((np.asarray(t_us) - 1000) // 1000, 0, n_steps - 1)
        return z0 - (pz[k] + tz[k] * ((np.asarray(t_us) - 1000) - k * 1000) * 1e-6)

    return events, rows, intrinsics, true_depth


@pytest.mark.parametrize("profile", ["constant", "changing"])
def test_forward_motion_gives_the_depth_where_the_image_speeds_up(profile):
    # constant: the kernel works in time (its points' times scaled by their own image speed); changing: in
    # travel, each point's travel taken with its own pixel's gains. With the event's gains alone the slope came
    # out Z (1 + 3 e), e = 1 / (4 to 15 px) here: 20-75 % too deep.
    speed = (lambda k: 2.0) if profile == "constant" else (lambda k: 2.0 + 1.0 * np.sin(0.05 * k))
    events, rows, intrinsics, true_depth = forward_edge(speed)
    estimator = TimeSurfaceEstimator(TimeSurfaceConfig(SENSOR, intrinsics, per_pixel=True), t0_us=0)
    depth, quality = estimator.feed(events, rows)
    on_axis = depth["y"] == 11  # the row through the principal point: the motion there is along the edge's normal
    assert np.count_nonzero(on_axis) >= 5
    rel = depth["z"][on_axis] / true_depth(quality["t_event"][on_axis]) - 1
    assert np.max(np.abs(rel)) < 1e-3, rel  # (1e-5 measured: times are rounded to 1 µs)


def test_the_window_stops_where_the_image_motion_turned():
    ring, state = np.zeros((tt.RING, tt.N_R)), np.full(tt.N_S, tt.NOT_YET, np.int64)
    for k in range(100):  # 63° off +x for steps 0-59, then along +x
        tt.advance(ring, state, k, np.array([0.5, 1.0, 0.0] if k < 60 else [1.0, 0.0, 0.0]), 1e-3)
    along, across = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)  # g and c: image motion along f and across it per m/s

    def window(cos_turn):
        return tt.since_reversal(ring, 99, 99_500, 0, 1000, 0, *along, 0.0, 0.0, 0.0, 1e9, *across, cos_turn)

    assert window(0.0) == 99_500  # 90°: back to the first step (no reversal)
    assert window(float(np.cos(np.radians(45)))) == 39_500  # back to step 60, where the motion turned by 63°
    assert window(float(np.cos(np.radians(70)))) == 99_500


def oblique_edge(slant, n_steps=700, sub=20):
    """An edge ``u + slant v = c`` moved along +u by a translation (50 px/s at ``DEPTH``) while a rotation
    about x (up to 32 px/s at the centre, changing every step) moves it across, integrated in ``sub`` parts
    per 1 ms step through the exact rotational flow; and its velocity rows (six columns)."""
    k = np.arange(n_steps)
    wx = 20.0 / F * (0.6 * np.sin(0.21 * k) + np.sin(0.013 * k))
    tx = -50.0 * DEPTH / F
    marks_v = np.linspace(-60.0, SENSOR[1] + 60.0, 400)  # points of the edge, followed through the flow
    marks_u = -slant * marks_v - 1.0
    ys, xs = np.mgrid[0:SENSOR[1], 0:SENSOR[0]]
    fired = np.full(ys.shape, -1, np.int64)
    for step in range(n_steps):
        for part in range(sub):
            bu, bv = rotational_flow(wx[step], 0.0, 0.0, marks_u, marks_v, F, F, INTRINSICS[2], INTRINSICS[3])
            marks_u = marks_u + (-F * tx / DEPTH + bu) * 1e-3 / sub
            marks_v = marks_v + bv * 1e-3 / sub
            order = np.argsort(marks_v)
            reached = np.interp(np.arange(SENSOR[1]), marks_v[order], marks_u[order])[:, None] >= xs
            fired[(fired < 0) & reached] = 1000 + step * 1000 + (part + 1) * 1000 // sub
    ok = fired >= 0
    t, x, y = fired[ok], xs[ok], ys[ok]
    filler = np.arange(1000, int(t.max()) + 1000, 1000)  # an OFF event at (0, 0) every step
    t_all = np.concatenate([t, filler])
    order = np.argsort(t_all, kind="stable")
    zeros = np.zeros(len(filler), np.int64)
    events = make_events(t_all[order], np.concatenate([x, zeros])[order], np.concatenate([y, zeros])[order],
                         np.concatenate([np.ones(len(t), np.int64), zeros])[order])
    zero = np.zeros(n_steps)
    velocity = np.column_stack([np.full(n_steps, tx), zero, zero, wx, zero, zero])
    velocity = np.concatenate([velocity[:1], velocity])

    def rows(first, count):
        return velocity[np.clip(np.arange(first, first + count), 0, len(velocity) - 1)], first

    return events, rows


@pytest.mark.parametrize("slant", [0.5, -0.7])
def test_a_rotation_across_the_motion_is_taken_out_of_the_lines(slant):
    # The rotation moves the oblique edge across f by up to 2 px over a window: along a line of pixels the
    # edge arrives early or late by slant times that. Net of the rotation across f too, each point is on
    # the line of its track (and beta takes out where on it): the code before was 14-19 % off (median).
    events, rows = oblique_edge(slant)
    depth, _, _ = run(events, rows)
    assert len(depth) > 400
    error = np.abs(depth["z"] / DEPTH - 1)
    assert np.median(error) < 1e-3, np.median(error)  # (2e-4 measured)


def test_points_move_to_the_line_of_their_track_where_the_velocity_turned():
    ring, state = np.zeros((tt.RING, tt.N_R)), np.full(tt.N_S, tt.NOT_YET, np.int64)
    for k in range(100):  # across f (+v) at 0.1 m/s for steps 0-49, then along f (+u)
        tt.advance(ring, state, k, np.array([0.0, 0.1, 0.0] if k < 50 else [0.1, 0.0, 0.0]), 1e-3)
    middle = 7
    # the event, a point since the turn, one from 20.5 ms before it, and one that moves past the lines
    ps_, pw, pt = np.array([0.0, -1.0, -2.0, -2.0]), np.array([0.0, 1.0, -1.0, 6.0]), np.array([0.0, -30e3, -70e3,
                                                                                                   -70e3])
    pg = middle + np.floor(pw + 0.5).astype(np.int64)
    depth = 1e-3  # m: 0.1 m/s across for 20.5 ms moves a point 2.05 px with q = (0, 1, 0) px per m/s
    n = tt.to_travel(ring, ps_, pw, pt, pg, 4, 99_500, 0, 1000, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, depth, 1e9,
                     0.0, 1.0, 0.0, 0.0, 0.0, 0.0, middle)
    assert n == 3  # the last one's line, 6 + 2.05 px across, is past the 2 middle lines
    np.testing.assert_allclose(pw[:3], [0.0, 1.0, 1.05])
    assert list(pg[:3]) == [middle, middle + 1, middle + 1]
    np.testing.assert_allclose(pt[:3], [0.0, -3e-3, -4.95e-3])  # travel along f since (px·m), the turn included
