"""Coverage and error by true-depth band and by motion phase (``tofnet.eval.breakdown``)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.eval.breakdown import PHASES, by_depth_band, by_motion_phase, motion_phase
from tofnet.eval.match import match_estimates
from tofnet.events import DEPTH_DTYPE, make_events
from tofnet.io import write_depth, write_ecd
from tofnet.io.recording import Intrinsics
from tofnet.sim.camera import Segment, Trajectory


def _estimates(x, z, step=2):
    depth = np.empty(len(x), DEPTH_DTYPE)
    depth["step"], depth["t"], depth["y"] = step, 0, 0
    depth["x"], depth["z"] = x, z
    return depth


def test_bands_count_the_events_of_each_band_and_the_estimates_they_triggered():
    # Six events in step 0 at pixels 0..5: true depths 0.5, 1.5, 1.7, 3, 6, 9 m.
    events = make_events([0] * 6, list(range(6)), [0] * 6, [1] * 6)
    gt = np.array([0.5, 1.5, 1.7, 3.0, 6.0, 9.0])
    depth = _estimates([1, 2, 4], [1.65, 1.7, 5.4])  # two in 1-2 m, one in 4-8 m
    matches = match_estimates(depth, events, gt, t0_us=0, timestep_us=1000, latency_steps=2)
    bands = {b.label: b for b in by_depth_band(depth, matches, gt)}
    assert [b.events for b in bands.values()] == [1, 2, 1, 1, 1]
    assert [b.estimates for b in bands.values()] == [0, 2, 0, 1, 0]
    assert bands["1-2 m"].coverage == pytest.approx(1.0)
    assert bands["4-8 m"].coverage == pytest.approx(1.0) and bands["2-4 m"].coverage == 0
    assert bands["1-2 m"].errors.median_rel_pct == pytest.approx(5.0)  # 10 % and 0 %
    assert bands["4-8 m"].errors.bias_rel_pct == pytest.approx(-10.0)
    assert math.isnan(bands["< 1 m"].errors.median_rel_pct)


def test_phase_marks_a_reversal_for_the_window_after_it_and_steady_elsewhere():
    # +x for 0.5 s, then -x for 0.5 s: reversal from 0.5 s for 100 ms.
    trajectory = Trajectory((0.0, 0.0, 0.0), (Segment(0.5, (0.5, 0.0, 0.0)), Segment(0.5, (-0.5, 0.0, 0.0))))
    t = np.array([0.2, 0.45, 0.51, 0.59, 0.62, 0.9])
    assert motion_phase(trajectory, t).tolist() == [0, 0, 1, 1, 0, 0]


def test_phase_calls_slow_motion_a_reversal():
    trajectory = Trajectory((0.0, 0.0, 0.0), (Segment(0.5, (0.5, 0.0, 0.0)), Segment(0.2, (0.05, 0.0, 0.0)),
                                               Segment(0.5, (0.5, 0.0, 0.0))))
    assert motion_phase(trajectory, np.array([0.3, 0.6, 0.9])).tolist() == [0, 1, 0]


def test_phases_split_coverage_by_the_time_of_the_triggering_event():
    trajectory = Trajectory((0.0, 0.0, 0.0), (Segment(0.5, (0.5, 0.0, 0.0)), Segment(0.5, (-0.5, 0.0, 0.0))))
    events = make_events([200_000, 200_000, 520_000, 520_000], [0, 1, 0, 1], [0] * 4, [1] * 4)
    gt = np.ones(4)
    depth = np.concatenate([_estimates([0, 1], [1.0, 1.0], step=202), _estimates([0], [1.2], step=522)])
    matches = match_estimates(depth, events, gt, t0_us=0, timestep_us=1000, latency_steps=2)
    steady, reversal = by_motion_phase(depth, matches, events, trajectory)
    assert (steady.label, reversal.label) == PHASES
    assert (steady.events, steady.estimates, reversal.events, reversal.estimates) == (2, 2, 2, 1)
    assert reversal.errors.median_rel_pct == pytest.approx(20.0)


def test_eval_prints_and_writes_the_bands(tmp_path, capsys):
    events = make_events([10_000, 10_100, 10_200, 160_000], [0, 1, 2, 3], [0, 0, 0, 0], [1, 1, 1, 1])
    write_ecd(tmp_path / "rec", events, intrinsics=Intrinsics(10, 10, 2, 2), sensor_size=(4, 1),
              gt_depth=np.array([1.0, 2.0, 5.0, 4.0]))
    depth = np.empty(3, DEPTH_DTYPE)
    depth["step"], depth["t"], depth["y"] = 2, 13_000, 0
    depth["x"], depth["z"] = [0, 1, 2], [1.1, 1.8, 4.0]
    write_depth(tmp_path / "depth.npz", depth, t0_us=10_000, timestep_us=1000, latency_steps=2)
    assert main(["eval", str(tmp_path / "rec"), str(tmp_path / "depth.npz"), "--json", str(tmp_path / "m.json")]) == 0
    text = capsys.readouterr().out
    assert "by true depth" in text and "4-8 m" in text
    assert "by motion phase: not available" in text  # no poses
    data = json.loads((tmp_path / "m.json").read_text())
    bands = {b["group"]: b for b in data["depth_bands"]}
    assert (bands["1-2 m"]["events"], bands["1-2 m"]["estimates"]) == (1, 1)  # 1.0 m is in 1-2 m
    assert (bands["2-4 m"]["events"], bands["2-4 m"]["estimates"]) == (1, 1)
    assert (bands["4-8 m"]["events"], bands["4-8 m"]["estimates"]) == (2, 1)
    assert data["motion_phases"] is None


def test_a_steady_run_has_no_reversal_up_to_its_last_event():
    trajectory = Trajectory((0.0, 0.0, 0.0), (Segment(0.3, (0.5, 0.0, 0.0)),))  # stands still after 0.3 s
    t = np.array([0.0, 0.1, 0.2999, 0.29999])
    assert motion_phase(trajectory, t).tolist() == [0, 0, 0, 0]


def test_the_motion_phase_grid_is_counted_before_it_is_made():
    """Events two hours apart make a grid of 7.2 million 1 ms cells; ten times the bound (a hostile file's times) is one
    line before anything is allocated."""
    from tofnet.errors import DataError
    from tofnet.eval.breakdown import MAX_PHASE_CELLS, PHASE_STEP_S

    class Steady:
        def velocity_at(self, t):
            return np.tile([0.5, 0.0, 0.0], (len(np.atleast_1d(t)), 1))

    assert motion_phase(Steady(), np.array([0.0, 7200.0])).tolist() == [0, 0]
    span = MAX_PHASE_CELLS * PHASE_STEP_S * 10
    with pytest.raises(DataError, match=r"the events, over 1e\+06 s, make 1,000,000,100 motion-phase cells of 1 ms, "
                                        r"more than the 100,000,000 allowed; score a time window"):
        motion_phase(Steady(), np.array([0.0, span]))
