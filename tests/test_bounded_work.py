"""Bounded work for small files (issue 27 item 6): plan grids and globs, compile time, huge values."""

import glob
import time
import warnings

import numpy as np
import pytest

from tofnet.batch import PlanError, load_plan
from tofnet.errors import DataError
from tofnet.events import make_events


def test_compile_converts_the_source_cores_once_per_connection_not_once_per_core(monkeypatch):
    # traffic_of turned a list of core indices into an array inside its per-core loop:
    # quadratic (~58 s for 1x1 patches at 240x180). Count list conversions instead of timing.
    import tofnet.compiler.partition as partition
    from tofnet.compiler import compile_network
    from tofnet.networks import depth_network

    conversions = []

    class CountingNumpy:
        def __getattr__(self, name):
            return getattr(np, name)

        def asarray(self, value, *args, **kwargs):
            if isinstance(value, (list, tuple)):
                conversions.append(len(value))
            return np.asarray(value, *args, **kwargs)

    monkeypatch.setattr(partition, "np", CountingNumpy())
    compiled = compile_network(depth_network((16, 12)), patch=(1, 1))
    assert compiled.cores_used == 2 * 16 * 12
    assert len(conversions) <= len(compiled.traffic)  # at most one per connection


def _gyroscope(values, bias):
    from tofnet.io.rotation import Gyroscope
    times = np.arange(len(values)) * 0.01
    gyro = np.zeros((len(values), 3))
    gyro[:, 0] = values
    return Gyroscope(times, gyro, bias=bias)


@pytest.mark.parametrize("values, bias", [
    ([1.797e308] * 3, [-1.797e308, 0, 0]),          # overflows in g - bias
    ([1.797e308, -1.797e308, 1.797e308], [0, 0, 0]),  # overflows interpolating between samples
])
def test_a_huge_gyro_value_is_one_line_without_numpy_warnings(values, bias):
    from tofnet.models.binding import angular_velocity_table
    gyroscope = _gyroscope(values, bias)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's RuntimeWarning must not come first
        with pytest.raises(DataError, match="angular velocity is not finite at t = ") as err:
            angular_velocity_table(gyroscope, 0, 1000, 3, 4)
    assert "\n" not in str(err.value)


# ---------------------------------------------------------------- plans

@pytest.fixture
def folder(tmp_path):
    np.save(tmp_path / "a.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 0]))
    return tmp_path


def test_a_huge_grid_is_refused_from_its_sizes_before_it_is_expanded(folder, monkeypatch):
    from tofnet.batch.plan import Plan

    def never(self):
        raise AssertionError("the grid was expanded")
    monkeypatch.setattr(Plan, "combinations", never)
    values = {"refractory": [f"{k}ms" for k in range(1, 41)], "timestep": [f"{k}us" for k in range(100, 140)],
              "distance": list(range(1, 41)), "counter-bits": list(range(1, 21)), "update-every": list(range(1, 6))}
    text = "recordings: [a.npy]\ngrid:\n" + "".join(f"  {k}: {v}\n" for k, v in values.items())
    assert len(text) < 1500  # a small file: 40 * 40 * 40 * 20 * 5 = 6.4 M grid points
    (folder / "plan.yaml").write_text(text)
    started = time.perf_counter()
    with pytest.raises(PlanError, match=r"plan.yaml:2: grid: 1 recordings x 1 networks x \(40 x 40 x 40 x 20 x 5\) "
                                        r"grid points = 6,400,000 tasks; a plan may have at most 10,000"):
        load_plan(folder / "plan.yaml")
    assert time.perf_counter() - started < 10


def test_a_plan_at_the_limit_is_accepted(folder):
    from tofnet.batch.bounds import MAX_TASKS, task_count
    assert task_count(1, 1, [100, 100]) == MAX_TASKS  # the boundary the docs state
    (folder / "plan.yaml").write_text("recordings: [a.npy]\ngrid: {distance: [1, 2], counter-bits: [6, 7, 8]}\n")
    assert load_plan(folder / "plan.yaml").size() == 6


def test_a_relative_glob_never_leaves_the_plans_folder(folder):
    sub = folder / "sub"
    sub.mkdir()
    (sub / "plan.yaml").write_text("recordings: ['../*.npy']\n")
    with pytest.raises(PlanError, match=r"plan.yaml:1: recordings\[0\]: '../\*.npy' leaves the plan's folder"):
        load_plan(sub / "plan.yaml")
    (sub / "plan.yaml").write_text(f"recordings: ['{folder}/*.npy']\n")  # absolute: the user said where
    assert [r.name for r in load_plan(sub / "plan.yaml").recordings] == ["a"]


def test_a_glob_of_the_whole_file_system_stops_after_a_bounded_walk(folder):
    (folder / "plan.yaml").write_text("recordings: ['/**/*.no-such-suffix']\n")
    started = time.perf_counter()
    with pytest.raises(PlanError, match=r"recordings\[0\]: '/\*\*/\*.no-such-suffix' looks at more than 100,000 "
                                        r"files and folders; give a narrower pattern"):
        load_plan(folder / "plan.yaml")
    assert time.perf_counter() - started < 30


def test_the_bounded_glob_matches_what_glob_matches(folder, monkeypatch):
    from tofnet.batch import bounds
    for path in ("x/a.npy", "x/y/b.npy", "x/y/z/c.npz", ".hidden/d.npy", "x/.e.npy", "f.npy"):
        (folder / path).parent.mkdir(parents=True, exist_ok=True)
        (folder / path).write_bytes(b"")
    for pattern in ("*.npy", "**/*.npy", "x/**/*.np?", "x/*/*.npy", "**", "x/**", "[fx]*", "x/y", ".*/*.npy"):
        expected = sorted(glob.glob(str(folder / pattern), recursive=True))
        assert [str(p).rstrip("/") for p in bounds.bounded_glob(pattern, folder)] == \
            [p.rstrip("/") for p in expected], pattern
    (folder / "x" / "loop").symlink_to(folder)  # ** does not follow symlinked folders
    assert len(bounds.bounded_glob("**/*.npy", folder)) == 4
    monkeypatch.setattr(bounds, "MAX_GLOB_ENTRIES", 5)
    (folder / "plan.yaml").write_text("recordings: ['**/*.npy']\n")
    with pytest.raises(PlanError, match="looks at more than 5 files and folders"):
        load_plan(folder / "plan.yaml")


def test_a_repeated_grid_value_is_named_alone_not_the_whole_list(folder):
    # Found by the "plan imports" fuzz target: the message quoted the whole list (1,400 characters).
    (folder / "plan.yaml").write_text(f"recordings: [a.npy]\ngrid:\n  update-every: {list(range(1, 300)) + [7]}\n")
    with pytest.raises(PlanError) as err:
        load_plan(folder / "plan.yaml")
    assert str(err.value) == f"{folder / 'plan.yaml'}:3: grid.update-every: the value 7 is repeated"


@pytest.mark.parametrize("entry", ["{spec: '%s'}", "{glob: '%s*'}", "'%s'", "{glob: '../%s*'}"])
def test_a_very_long_name_in_a_plan_is_one_short_line(folder, entry):
    # Found by the "plan imports" fuzz target: OSError (file name too long) and 5,000-character messages.
    key = "networks" if "spec" in entry else "recordings"
    other = "recordings: [a.npy]\n" if key == "networks" else ""
    (folder / "plan.yaml").write_text(f"{other}{key}: [{entry % ('9' * 5000)}]\n")
    with pytest.raises(PlanError) as err:
        load_plan(folder / "plan.yaml")
    assert "\n" not in str(err.value) and len(str(err.value)) < 600


def test_a_plans_scenario_duration_is_bounded_when_the_plan_is_read(folder):
    # The simulator's limit (3600 s), checked with the plan's file, line and key instead of at expansion.
    (folder / "plan.yaml").write_text("recordings:\n  - {scenario: slider, duration: 1e9}\n")
    with pytest.raises(PlanError, match=r"plan.yaml:2: recordings\[0\].duration: expected a positive number of "
                                        r"seconds, at most 3600, got 1000000000.0"):
        load_plan(folder / "plan.yaml")
