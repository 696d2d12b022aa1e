"""Matching estimates to ground truth and the accuracy metrics, on hand-sized arrays."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.eval import evaluate, evaluate_arrays, match_estimates
from tofnet.events import DEPTH_DTYPE, make_events
from tofnet.io.recording import Recording

DT = 1000  # µs


def depth_of(rows, t0_us: int = 0, dt: int = DT) -> np.ndarray:
    """Estimates from ``(step, x, y, z)`` rows, stamped at the end of their step."""
    out = np.empty(len(rows), dtype=DEPTH_DTYPE)
    for i, (step, x, y, z) in enumerate(rows):
        out[i] = (t0_us + (step + 1) * dt, x, y, z, step)
    return out


def match(depth, events, gt, t0_us=0, latency=2):
    return match_estimates(depth, events, gt, t0_us=t0_us, timestep_us=DT, latency_steps=latency)


def test_estimate_in_step_s_is_matched_to_the_event_of_step_s_minus_latency():
    # The same pixel fires in steps 8, 9 and 10 with distinct true depths.
    events = make_events([8_100, 9_100, 10_100], [5, 5, 5], [3, 3, 3], [1, 1, 1])
    gt = np.array([1.0, 2.0, 3.0])
    m = match(depth_of([(10, 5, 3, 1.1)]), events, gt)
    assert m.gt.tolist() == [1.0]  # step 8, not 9 (s-1) nor 10 (s)
    assert m.event_index.tolist() == [0]
    assert m.input_step.tolist() == [8]
    # With another latency the same estimate pairs with another event.
    assert match(depth_of([(10, 5, 3, 1.1)]), events, gt, latency=1).gt.tolist() == [2.0]


def test_first_event_of_the_pixel_in_the_step_is_used():
    events = make_events([8_100, 8_400, 8_900], [5, 5, 5], [3, 3, 3], [1, 0, 1])
    m = match(depth_of([(10, 5, 3, 1.0)]), events, np.array([1.5, 7.0, 9.0]))
    assert m.gt.tolist() == [1.5]
    assert m.event_index.tolist() == [0]


def test_other_pixels_and_steps_do_not_match_and_are_counted():
    events = make_events([8_100, 8_200, 9_000], [5, 6, 5], [3, 4, 4], [1, 1, 1])
    gt = np.array([1.0, 2.0, 3.0])
    # (6, 3): no event there; (5, 3) at step 11 -> input step 9: no event of that pixel.
    m = match(depth_of([(10, 6, 3, 1.0), (11, 5, 3, 1.0), (10, 6, 4, 2.5), (1, 5, 3, 1.0)]), events, gt)
    assert m.event_index.tolist() == [-1, -1, 1, -1]
    assert np.isnan(m.gt[[0, 1, 3]]).all() and m.gt[2] == 2.0
    assert m.n_unmatched == 3


def test_input_step_is_measured_from_t0():
    # t0 = 500 µs: t = 1499 is in step 0 and t = 1500 in step 1.
    events = make_events([1_499, 1_500], [2, 2], [2, 2], [1, 1])
    m = match_estimates(depth_of([(2, 2, 2, 1.0), (3, 2, 2, 1.0)], t0_us=500), events, np.array([4.0, 6.0]),
                        t0_us=500, timestep_us=DT, latency_steps=2)
    assert m.gt.tolist() == [4.0, 6.0]


def test_matching_agrees_with_a_brute_force_search():
    rng = np.random.default_rng(3)
    n = 3000
    t = np.sort(rng.integers(0, 50_000, n))
    events = make_events(t, rng.integers(0, 8, n), rng.integers(0, 6, n), rng.integers(0, 2, n))
    gt = rng.uniform(0.5, 5.0, n)
    steps = rng.integers(0, 55, 400)
    depth = depth_of([(s, x, y, 1.0) for s, x, y in zip(steps, rng.integers(0, 9, 400), rng.integers(0, 7, 400))])
    m = match(depth, events, gt)
    ev_step = t // DT
    for i, est in enumerate(depth):
        hits = np.flatnonzero((events["x"] == est["x"]) & (events["y"] == est["y"]) & (ev_step == est["step"] - 2))
        assert m.event_index[i] == (hits[0] if len(hits) else -1)


def test_metrics_are_the_papers_errors():
    events = make_events([0, 100, 200, 300, 400], [0, 1, 2, 3, 4], [0, 0, 0, 0, 0], [1] * 5)
    gt = np.array([1.0, 2.0, 5.0, 4.0, 2.0])
    depth = depth_of([(2, 0, 0, 1.1), (2, 1, 0, 1.8), (2, 2, 0, 4.0)])
    ev = evaluate_arrays(depth, events, gt, t0_us=0, timestep_us=DT, latency_steps=2, window_s=0)
    # |err| = 0.1, 0.2, 1.0 m; relative 10, 10, 20 %.
    assert ev.errors.n == 3
    assert ev.errors.mean_abs_m == pytest.approx(1.3 / 3)
    assert ev.errors.median_abs_m == pytest.approx(0.2)
    assert ev.errors.mean_rel_pct == pytest.approx(40 / 3)
    assert ev.errors.median_rel_pct == pytest.approx(10.0)
    assert ev.errors.bias_rel_pct == pytest.approx(-10.0)  # signed: +10, -10, -20 %
    assert ev.coverage == pytest.approx(3 / 5)
    assert (ev.events_in, ev.estimates, ev.unmatched, ev.gt_invalid) == (5, 3, 0, 0)
    assert ev.windows == []


def test_unmatched_and_invalid_ground_truth_are_counted_not_averaged():
    events = make_events([0, 100, 200], [0, 1, 2], [0, 0, 0], [1, 1, 1])
    gt = np.array([2.0, np.nan, 0.0])
    depth = depth_of([(2, 0, 0, 3.0), (2, 1, 0, 9.0), (2, 2, 0, 9.0), (2, 7, 7, 9.0)])
    ev = evaluate_arrays(depth, events, gt, t0_us=0, timestep_us=DT, latency_steps=2, window_s=0)
    assert (ev.estimates, ev.matched, ev.unmatched, ev.gt_invalid) == (4, 1, 1, 2)
    assert ev.errors.mean_abs_m == pytest.approx(1.0)
    assert ev.errors.median_rel_pct == pytest.approx(50.0)
    assert ev.coverage == pytest.approx(4 / 3)  # estimates / events, whatever they matched


def test_windows_split_by_the_triggering_input_step():
    # Events in steps 0, 1 (window 0, 2 ms windows) and 2, 3 (window 1); step 5 in window 2.
    events = make_events([0, 1_000, 2_000, 3_000, 5_000], [1, 1, 1, 1, 1], [1] * 5, [1] * 5)
    gt = np.array([1.0, 2.0, 4.0, 4.0, 1.0])
    # The estimate of the step-1 event is emitted in step 3, yet belongs to window 0.
    depth = depth_of([(2, 1, 1, 1.5), (3, 1, 1, 2.0), (4, 1, 1, 5.0), (5, 1, 1, 4.0)])
    ev = evaluate_arrays(depth, events, gt, t0_us=0, timestep_us=DT, latency_steps=2, window_s=0.002)
    assert [(w.start_s, w.end_s) for w in ev.windows] == [(0.0, 0.002), (0.002, 0.004), (0.004, 0.006)]
    assert [w.events_in for w in ev.windows] == [2, 2, 1]
    assert [w.estimates for w in ev.windows] == [2, 2, 0]
    assert [w.coverage for w in ev.windows] == [1.0, 1.0, 0.0]
    w0, w1, w2 = (w.errors for w in ev.windows)
    assert w0.mean_abs_m == pytest.approx(0.25) and w0.median_rel_pct == pytest.approx(25.0)
    assert w1.mean_abs_m == pytest.approx(0.5) and w1.mean_rel_pct == pytest.approx(12.5)
    assert w2.n == 0 and math.isnan(w2.mean_abs_m)
    assert sum(w.estimates for w in ev.windows) == ev.estimates


def test_json_and_table_are_readable_and_have_no_nan():
    events = make_events([0, 5_000], [1, 1], [1, 1], [1, 1])
    depth = depth_of([(2, 1, 1, 1.2)])
    ev = evaluate_arrays(depth, events, np.array([1.0, 1.0]), t0_us=0, timestep_us=DT, latency_steps=2,
                         window_s=0.002)
    data = json.loads(ev.to_json())
    assert data["mean_rel_pct"] == pytest.approx(20.0)
    assert data["windows"][1]["mean_abs_m"] is None  # empty window: undefined, not NaN
    assert data["latency_steps"] == 2 and data["estimates"] == 1
    text = ev.table()
    assert "abs error [m]" in text and "rel error [%]" in text and "20.00" in text
    assert "coverage 50.00 %" in text


def test_evaluate_needs_ground_truth_depth():
    rec = Recording(events=make_events([0], [0], [0], [1]), source="slider_depth")
    with pytest.raises(DataError, match="events_depth.npy"):
        evaluate(rec, depth_of([]), {"t0_us": 0, "timestep_us": DT, "latency_steps": 2})


def test_evaluate_uses_the_depth_metadata():
    events = make_events([10_000, 11_000], [3, 3], [3, 3], [1, 1])
    rec = Recording(events=events, gt_depth=np.array([2.0, 4.0]))
    depth = depth_of([(2, 3, 3, 2.0)], t0_us=10_000)
    ev = evaluate(rec, depth, {"t0_us": 10_000, "timestep_us": DT, "latency_steps": 1})
    assert ev.errors.mean_abs_m == pytest.approx(2.0)  # step 2 - 1 = step 1: the 4 m event
    with pytest.raises(DataError, match="lacks latency_steps"):
        evaluate(rec, depth, {"t0_us": 0, "timestep_us": DT})


def test_windows_are_counted_and_bounded_before_any_is_made(monkeypatch):
    """An estimate at step 2.3e15 (2**61 µs after t0) made 2.3e13 windows of 100 ms: bincount asked for 82 TiB.
    The count is one line naming the field and the fix; the error figure (an automatic band window of 200 times
    the span overflowed int64) draws, and refuses a band window giving more than MAX_METRIC_WINDOWS bands."""
    from tofnet.eval import plots_error
    from tofnet.eval.plots import error_figure
    from tofnet.units import MAX_METRIC_WINDOWS

    events = make_events([0, 1_000, 2_000], [1, 1, 1], [1, 1, 1], [1, 1, 1])
    far = (2**61 - 2) // DT - 1
    depth = depth_of([(2, 1, 1, 1.0), (far, 1, 1, 2.0)])
    with pytest.raises(DataError, match=rf"^per-window metrics: the estimates \(array 'step' to {far}\), reaching "
                                        rf".* make 23,058,430,092,137 windows of 100 ms, more than the "
                                        rf"{MAX_METRIC_WINDOWS:,} allowed; give a longer --window"):
        evaluate_arrays(depth, events, np.ones(3), t0_us=0, timestep_us=DT, latency_steps=2, window_s=0.1)
    rec = Recording(events=events, gt_depth=np.ones(3), source="rec")
    meta = {"t0_us": 0, "timestep_us": DT, "latency_steps": 2}
    assert error_figure(rec, depth, meta).axes  # drawn, one band
    monkeypatch.setattr(plots_error, "MAX_METRIC_WINDOWS", 1_000)  # the same check, on a small figure
    with pytest.raises(DataError, match="the error bands over 3.001 ms make 3,001 windows of 1 µs, more than the "
                                        "1,000 allowed; give a longer --error-window"):
        error_figure(rec, depth_of([(2, 1, 1, 1.0)]), meta, window_s=1e-6)
