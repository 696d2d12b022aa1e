"""Evaluation of a real backend run on a small simulated recording: the timing conventions agree."""

from __future__ import annotations

import pytest

from tofnet.eval import evaluate


@pytest.fixture(scope="module")
def run_result():
    from tofnet.api import run
    from tofnet.sim.engine import generate
    from tofnet.sim.scenarios import scenario

    recording = generate(scenario("slider", 0.15).replace(sensor_size=(64, 48)), seed=1).to_recording()
    result, _ = run(recording, backend="reference")
    return recording, result


def test_every_estimate_of_a_run_finds_its_triggering_event(run_result):
    recording, result = run_result
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
    ev = evaluate(recording, result.depth, meta)
    assert result.latency_steps == 2
    assert ev.estimates == len(result.depth) > 100
    assert ev.unmatched == 0 and ev.gt_invalid == 0 and ev.matched == ev.estimates
    assert ev.coverage == pytest.approx(len(result.depth) / result.events_in)
    assert sum(w.estimates for w in ev.windows) == ev.estimates
    assert sum(w.events_in for w in ev.windows) == result.events_in


def test_a_wrong_latency_leaves_estimates_unmatched(run_result):
    recording, result = run_result
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": 1}
    assert evaluate(recording, result.depth, meta).unmatched > 0.5 * len(result.depth)
