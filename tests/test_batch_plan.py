"""Batch plans: what they expand to, and one-line errors naming file, line and key (no Dask needed)."""

import numpy as np
import pytest

from tofnet.batch import PlanError, expand, load_plan
from tofnet.cli import main
from tofnet.events import make_events


@pytest.fixture
def folder(tmp_path):
    for name in ("a", "b"):
        np.save(tmp_path / f"{name}.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 0]))
    (tmp_path / "net.yaml").write_text("processes:\n  inp: {type: InputProcess, sensor_size: [64, 48]}\n"
                                       "connections: []\n")
    return tmp_path


def write(folder, text):
    path = folder / "plan.yaml"
    path.write_text(text)
    return path


def test_a_plan_expands_to_recordings_x_networks_x_grid_in_plan_order(folder):
    plan = load_plan(write(folder, "recordings:\n  - '*.npy'\n  - {scenario: [slider, forward], duration: 50ms, "
                                   "seed: 3, sensor_size: 64x48}\n"
                                   "networks: [paper, {spec: paper, name: float, backend: float}]\n"
                                   "grid:\n  refractory: [20ms, 0.04]\n  counter-bits: 6\n"))
    assert [r.name for r in plan.recordings] == ["a", "b", "slider", "forward"]
    assert plan.recordings[2].duration == pytest.approx(0.05) and plan.recordings[2].sensor_size == (64, 48)
    assert plan.grid == {"refractory": ["20ms", 0.04], "counter_bits": [6]}
    tasks = expand(plan)
    assert len(tasks) == plan.size() == 4 * 2 * 2
    assert [t.number for t in tasks] == list(range(16))
    first = tasks[0]
    assert first.recording.name == "a" and first.network.name == "paper" and first.parameters == \
        {"refractory": "20ms", "counter_bits": 6}
    assert tasks[1].parameters["refractory"] == 0.04 and tasks[2].backend == "float"
    assert len({t.task_id for t in tasks}) == 16 and first.task_id.startswith("a.paper.refractory=20ms.counter_bits=6-")
    scenario_tasks = [t for t in tasks if t.recording.scenario == "slider"]
    assert len({t.scenario_folder for t in scenario_tasks}) == 1
    assert plan.output == folder / "plan-results" and plan.cache == plan.output / "scenarios"


def test_a_grid_sweeps_one_process_parameter_as_tofnet_run_set_does(folder):
    plan = load_plan(write(folder, "recordings: [a.npy]\nnetworks: [{estimator: improved}]\n"
                                   "grid:\n  time_surface.burst_surfaces: [1, 4]\n"))
    tasks = expand(plan)
    assert [t.parameters for t in tasks] == [{"time_surface.burst_surfaces": 1}, {"time_surface.burst_surfaces": 4}]
    assert tasks[1].task_id.startswith("a.improved.time_surface.burst_surfaces=4-")


def test_a_grid_may_not_point_a_process_at_a_file(folder):
    """Every parameter that names a file a process reads (``reads_file``) is refused in a grid: the
    angular velocity's gyroscope file as its samples."""
    from pathlib import Path
    spec = Path(__file__).resolve().parents[1] / "examples" / "rotation.yaml"
    for param in ("imu", "samples"):
        with pytest.raises(PlanError, match=f"angular_velocity.{param} names a file a process reads"):
            load_plan(write(folder, f"recordings: [a.npy]\nnetworks: [{spec}]\n"
                                    f"grid:\n  angular_velocity.{param}: [/etc/passwd]\n"))


def test_task_ids_survive_an_edit_of_the_plan_and_change_with_what_a_task_computes(folder):
    before = {t.task_id for t in expand(load_plan(write(folder, "recordings: [a.npy]\ngrid: {refractory: [20ms]}\n")))}
    after = [t.task_id for t in expand(load_plan(write(folder, "recordings: [a.npy, b.npy]\n"
                                                                "grid: {refractory: [20ms, 60ms]}\n")))]
    assert before < set(after) and len(after) == 4
    other_seed = expand(load_plan(write(folder, "recordings: [{scenario: slider, seed: 1}]\n")))[0]
    seed_0 = expand(load_plan(write(folder, "recordings: [{scenario: slider}]\n")))[0]
    assert other_seed.task_id != seed_0.task_id and other_seed.scenario_folder != seed_0.scenario_folder


@pytest.mark.parametrize("text, line, expected", [
    ("recordings: [a.npy]\ngird: {}\n", 2, "gird: unknown key"),
    ("name: x\n", 1, "recordings: missing"),
    ("recordings:\n  - a.npy\n  - missing.npy\n", 3, "recordings[1]: "),
    ("recordings:\n  - '*.txt'\n", 2, "matches nothing"),
    ("recordings:\n  - {scenario: slidr}\n", 2, "unknown scenario 'slidr'"),
    ("recordings:\n  - {scenario: slider,\n     duration: -1}\n", 3, "recordings[0].duration: expected a positive"),
    ("recordings:\n  - {scenario: slider, sensor_size: 0x4}\n", 2, "recordings[0].sensor_size"),
    ("recordings:\n  - {scenario: slider, colour: red}\n", 2, "recordings[0].colour: unknown key"),
    ("recordings: [a.npy, {path: a.npy}]\n", 1, "'a' is already used"),
    ("recordings: [a.npy]\nnetworks:\n  - nope.yaml\n", 3, "no such spec file"),
    ("recordings: [a.npy]\nnetworks:\n  - {spec: paper, estimator: time_surface}\n", 3,
     "networks[0].estimator: expected one of paper, improved, got 'time_surface'"),
    ("recordings: [a.npy]\nnetworks:\n  - {spec: net.yaml,\n     estimator: improved}\n", 4,
     "networks[0].estimator: picks a built-in network, and a spec names its own processes"),
    ("recordings: [a.npy]\nnetworks: [{estimator: improved}]\ngrid:\n  refractory: [0]\n", 4,
     "grid.refractory[0]: 0 for network 'improved': --refractory: the network has no InputProcess"),
    ("recordings: [a.npy]\nbackend: quantum\n", 2, "unknown backend 'quantum'"),
    ("recordings: [a.npy]\nnetworks:\n  - {spec: paper,\n     rotation: 'false'}\n", 4,
     "networks[0].rotation: expected true or false (false: as tofnet run --no-rotation), got 'false'"),
    ("recordings: [a.npy]\nkeep: [depth, everything]\n", 2, "keep[1]"),
    ("recordings: [a.npy]\ngrid:\n  speed: [1, 2]\n", 3, "grid.speed: unknown option"),
    ("recordings: [a.npy]\ngrid:\n  refractory:\n    - 20ms\n    - fast\n", 5, "grid.refractory[1]: 'fast'"),
    ("recordings: [a.npy]\ngrid:\n  distance: [1, 0]\n", 3, "expected at least 1 px"),
    ("recordings: [a.npy]\ngrid:\n  refractory: []\n", 3, "at least one value"),
    ("recordings: [a.npy]\ngrid:\n  time_surface.burst_surfaces: [4]\n", 3,
     "grid.time_surface.burst_surfaces[0]: 4 for network 'paper': network 'depth' has no process 'time_surface'"),
    ("recordings: [a.npy]\ngrid:\n  time_of_travel.distance: [2, 0]\n", 3,
     "grid.time_of_travel.distance[1]: 0 for network 'paper': time_of_travel.distance: expected at least 1 px"),
    ("recordings: [a.npy]\ngrid:\n  velocity.samples: [/etc/passwd]\n", 3,
     "velocity.samples names a file a process reads; a grid sweeps values, not files"),
    ("recordings: [a.npy]\ngrid:\n  distance: [1]\n  time_of_travel.distance: [2]\n", 2,
     "grid: for network 'paper': time_of_travel.distance is given twice (as distance too)"),
    ("recordings: [a.npy]\ngrid:\n  input.refractory: [null]\n", 3, "input.refractory: a value is required"),
    *((f"recordings:\n  - scenario: slider\n{key}: null\n", 3, f"{key}: expected a non-empty string, got null")
      for key in ("cache", "output", "name", "description", "backend")),  # TypeError, "None-results"
    ("recordings:\n  - {path: a.npy, name: ~}\n", 2, "recordings[0].name: expected a non-empty string, got null"),
    ("recordings:\n  - {path: }\n", 2, "recordings[0].path: expected a non-empty string, got null"),
    ("recordings: [a.npy\n", 2, "malformed YAML"),
    ("- scenario: slider\n", 1, "expected a mapping with keys name, description,"),
    ("- scenario: slider\n", 1, "recordings, networks, grid, backend, keep, intrinsics, calib, camera, velocity, columns, "
                              "topics, start, duration, until, side, rectify; got a list"),  # not the loader's '_Seq'
    ("recordings:\n  - {path: '*.raw', velocity: [0.3, 0, 0]}\n", 2,
     "no such file or folder; a pattern is written {glob: ...} (with the same reading keys) to match several"),
])
def test_errors_name_the_file_the_line_and_the_key(folder, text, line, expected):
    path = write(folder, text)
    with pytest.raises(PlanError) as err:
        load_plan(path)
    message = str(err.value)
    assert message.startswith(f"{path}:{line}: ") and expected in message and "\n" not in message


def test_a_bad_spec_names_its_own_file_and_line(folder):
    (folder / "bad.yaml").write_text("processes:\n  inp: {type: InputProcess, refractory: soon}\n")
    with pytest.raises(Exception) as err:
        load_plan(write(folder, "recordings: [a.npy]\nnetworks: [bad.yaml]\n"))
    assert f"{folder / 'bad.yaml'}:2:" in str(err.value)


def test_check_lists_the_tasks_without_running_them(folder, capsys):
    path = write(folder, "recordings: ['*.npy']\ngrid: {distance: [1, 2]}\n")
    assert main(["batch", str(path), "--check"]) == 0
    out = capsys.readouterr().out
    assert "2 recordings x 1 networks x 2 grid points = 4 tasks" in out and "b.paper.distance=2-" in out
    assert not (folder / "plan-results").exists()


def test_without_dask_the_command_says_which_extra_to_install(folder, capsys, monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    assert main(["batch", str(write(folder, "recordings: [a.npy]\n"))]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and 'pip install "tofnet[batch]"' in err


def test_the_example_plan_is_valid():
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "examples" / "batch" / "refractory_sweep.yaml"
    plan = load_plan(path)
    assert plan.size() == 40 and plan.output == path.parent / "refractory-sweep-results"
