"""Built-in scenarios, the ECD folders they write, and ``tofnet simulate``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import TofnetError
from tofnet.io.ecd import read_ecd
from tofnet.sim import SCENARIOS, scenario, simulate

SMALL = (48, 36)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_every_scenario_writes_a_readable_ecd_folder(name, tmp_path):
    summary = simulate(name, tmp_path / name, duration=0.02, seed=1, sensor_size=SMALL)
    assert summary["events"] > 0 and summary["max_render_step_px"] <= 0.25
    rec = read_ecd(tmp_path / name)
    assert len(rec.events) == summary["events"]
    assert rec.sensor_size == SMALL
    assert rec.gt_depth is not None and len(rec.gt_depth) == len(rec.events)
    assert 0.2 < rec.gt_depth.min() and rec.gt_depth.max() < 3.5
    assert rec.gt_depth.min() == pytest.approx(summary["depth_min"], rel=1e-6)
    # The field of view is kept: intrinsics scale with the sensor (240 -> 48 is a factor 5).
    assert rec.intrinsics.fx == pytest.approx(scenario(name).intrinsics.fx / 5)
    # The velocity read back from groundtruth.txt is the scenario's.
    config = scenario(name, 0.02)
    t = np.array([0.005, 0.0125])
    np.testing.assert_allclose(rec.trajectory.velocity_at(t), config.trajectory.velocity_at(t), atol=1e-6)


def test_scenarios_cover_the_papers_motions():
    speeds = {name: {tuple(s.velocity) for s in scenario(name).trajectory.segments} for name in SCENARIOS}
    assert speeds["slider"] == {(0.55, 0.0, 0.0)}
    assert {abs(v[0]) for v in speeds["fast_slider"]} == {2.6}
    assert all(v[1] == 0 and v[2] == 0 for v in speeds["fast_slider"])
    moving_axes = {axis for v in speeds["all_axes"] for axis in range(3) if v[axis] != 0}
    assert moving_axes == {0, 1, 2} and len(speeds["all_axes"]) >= 4
    assert speeds["forward"] == {(0.0, 0.0, 0.5)}
    # Every built-in scene keeps objects between 0.3 and 3.5 m over the default second.
    for name in SCENARIOS:
        scene = scenario(name).scene
        assert 0.3 <= min(o.center[2] for o in scene.objects) and scene.background_depth <= 3.5


def test_duration_scales_segments_and_replaces_config_duration():
    config = scenario("all_axes", 0.3)
    assert config.duration == 0.3
    assert config.trajectory.boundaries[-1] == pytest.approx(0.3)
    summary = simulate(config, None, duration=0.01, sensor_size=(32, 24))
    assert summary["duration_s"] == 0.01 and summary["files"] == [] and summary["sensor_size"] == (32, 24)


def test_unknown_scenario_names_the_known_ones():
    with pytest.raises(TofnetError) as err:
        simulate("nope", None)
    for name in SCENARIOS:
        assert name in str(err.value)


def test_cli_lists_scenarios(capsys):
    assert main(["simulate", "--list"]) == 0
    out = capsys.readouterr().out
    for name in SCENARIOS:
        assert name in out
    assert "0.55 m/s" in out and "2.60 m/s" in out


def test_cli_unknown_scenario_is_a_one_line_error(capsys, tmp_path):
    assert main(["simulate", "nope", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "unknown scenario 'nope'" in err and "slider" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_cli_writes_folder_and_summary(capsys, tmp_path):
    out = tmp_path / "run"
    code = main(["simulate", "vertical", str(out), "--duration", "0.02", "--seed", "4", "--sensor-size", "40x30",
                 "--quiet", "--json", str(tmp_path / "s.json")])
    assert code == 0
    text = capsys.readouterr().out
    assert "events" in text and "depth" in text and "events_depth.npy" in text
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["seed"] == 4 and summary["sensor_size"] == [40, 30]
    from tofnet.io.guard import MANIFEST
    assert sorted(p.name for p in out.iterdir() if p.name != MANIFEST) == sorted(summary["files"])
    assert summary["out_dir"] == str(out)  # not the temporary folder it was written in
    assert len(read_ecd(out).events) == summary["events"]
