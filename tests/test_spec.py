"""YAML network specs: loading, dumping, round trips and errors that name the line."""

from __future__ import annotations

import textwrap

import pytest

from tofnet import depth_network
from tofnet.compiler import LOIHI2, Budget
from tofnet.core.network import Network
from tofnet.core.process import Process
from tofnet.errors import SpecError
from tofnet.io.spec import (default_spec_path, dump_spec, load_budget, load_spec, network_from_dict,
                            network_to_dict, networks_equal, spec_from_dict, spec_to_dict)
from tofnet.processes import (AngularVelocityProcess, BackgroundActivityFilterProcess, DepthProcess, InputProcess,
                              TimeOfTravelProcess, TimeSurfaceProcess, UndistortProcess, VelocityProcess)

PAPER = """\
name: paper
processes:
  input:          {type: InputProcess, sensor_size: [240, 180], timestep: 1ms, refractory: 60ms}
  time_of_travel: {type: TimeOfTravelProcess, distance: 1, counter_bits: 8}
  depth:          {type: DepthProcess, min_depth: 0.05, max_depth: 20}
  velocity:       {type: VelocityProcess, source: groundtruth, per: patch, patch_size: 30}
connections:
  - input.events -> time_of_travel.events
  - time_of_travel.counts -> depth.counts
  - velocity.a_t -> depth.a_t
compile: {patch: [30, 30], budget: loihi2}
"""


def test_load_the_paper_spec():
    spec = load_spec(PAPER)
    assert networks_equal(spec.network, depth_network((240, 180)))
    assert spec.network.name == "paper" and spec.source == "<string>"
    assert spec.compile == {"patch": (30, 30), "budget": LOIHI2} and spec.backend is None
    assert spec.network.process("input").timestep == 0.001
    assert spec.compile_network().cores_used == 96


def test_default_spec_is_the_paper_network():
    path = default_spec_path()
    assert path.is_file()
    spec = load_spec(path)
    assert spec.source == str(path) and networks_equal(spec.network, depth_network((240, 180)))
    assert spec.compile_network().cores_used == 96


def every_parameter_changed() -> Network:
    """A network in which every parameter of every process type differs from its default."""
    inp = InputProcess(name="cam", sensor_size=(64, 48), timestep="250us", refractory="2.5ms",
                       refractory_per_polarity=True, t0=1.5)
    baf = BackgroundActivityFilterProcess(name="baf", radius=2, window="12ms")
    lens = UndistortProcess(name="lens", model="equidistant", coefficients=[-0.04, 0.01, -0.003, 0.0006],
                            intrinsics=[200.0, 201.5, 31.5, 23.5])
    tot = TimeOfTravelProcess(name="tot", distance=3, counter_bits=12)
    dep = DepthProcess(name="z", min_depth="10cm", max_depth=7.5, min_share=0.25)
    vel = VelocityProcess(name="v", source="samples", velocity=[0.1, -0.2, 0.3], samples="vel.txt", per="pixel",
                          patch_size=16, update_every=5, intrinsics=[200.0, 201.5, 31.5, 23.5],
                          distortion_model="equidistant", distortion=[-0.04, 0.01, -0.003, 0.0006])
    rot = AngularVelocityProcess(name="w", source="gyro", omega=[0.01, -0.02, 0.03], samples="w.txt", imu="imu.txt",
                                 rotation_cam_imu=[0.0, 0.0, 0.7071067811865476, 0.7071067811865476],
                                 time_shift="-2.5ms", bias=[0.001, 0.002, -0.003], update_every=3,
                                 intrinsics=[200.0, 201.5, 31.5, 23.5])
    surf = TimeSurfaceProcess(name="ts", sensor_size=(64, 48), timestep="250us", t0=1.5, model="plane", radius=2, coordinates="time",
                              ahead_px=0.5, window="30ms", window_depth=4.0, window_px=5.0, turn=0.3, min_points=6, min_spread=0.4,
                              outlier_px=0.3, iterations=4, max_rms_px=0.2, trim_px=0.5, hold_px=2.0, burst_ratio=3.0,
                              hold_fit_rms_px=0.8, behind_depth="8m", refractory_depth="8m", refractory="1ms", max_hold=0.5,
                              consistency=0.2, consistency_window="100ms", min_depth="10cm", max_depth=15.0,
                              min_denominator=0.2, max_turn=30.0, burst_surfaces=3, burst_fit="fitted")
    inp.events.connect(baf.events)
    baf.passed.connect(lens.events)
    lens.undistorted.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    rot.b_w.connect(dep.b_w)
    vel.a_t.connect(surf.a_t)
    rot.b_w.connect(surf.b_w)
    return Network([inp, baf, lens, tot, dep, vel, rot, surf], name="everything")


def test_every_process_type_and_parameter_round_trips():
    net = every_parameter_changed()
    for process in net.processes:  # the test covers every declared parameter
        defaults = {p.name: p.coerce(p.default, "x") for p in type(process).all_params() if p.name != "sensor_size"}
        assert all(process.values[k] != v for k, v in defaults.items()), process.name
    assert {type(p).__name__ for p in net.processes} == {
        name for name, cls in Process._registry.items() if cls.__module__.startswith("tofnet.processes")}
    for full in (False, True):
        text = dump_spec(net, full=full)
        again = load_spec(text).network
        assert networks_equal(again, net), text
        assert dump_spec(again, full=full) == text
        assert networks_equal(network_from_dict(network_to_dict(net, full=full)), net)
    assert "timestep: 250us" in dump_spec(net) and "refractory: 2.5ms" in dump_spec(net)


def test_spec_round_trip_keeps_compile_and_backend():
    text = PAPER.replace("compile: {patch: [30, 30], budget: loihi2}", textwrap.dedent("""\
        compile:
          patch: {time_of_travel: 30x30, depth: auto}
          budget: {name: tiny, core: {accumulators: 4096}, chip: {cores: 64}, max_chips: 3}
        backend: {name: multiproc, workers: 4}"""))
    spec = load_spec(text)
    assert spec.compile["patch"] == {"time_of_travel": (30, 30), "depth": "auto"}
    assert spec.budget == Budget.from_dict({"name": "tiny", "core": {"accumulators": 4096}, "chip": {"cores": 64},
                                            "max_chips": 3})
    assert (spec.backend, spec.backend_options) == ("multiproc", {"workers": 4})
    again = load_spec(dump_spec(spec))
    assert networks_equal(again.network, spec.network)
    assert (again.compile, again.backend, again.backend_options) == (spec.compile, "multiproc", {"workers": 4})
    assert spec_from_dict(spec_to_dict(spec)).compile == spec.compile


@pytest.mark.parametrize("backend, line, message", [
    ("{name: fixed, wokers: 2}", 0, "backend: backend 'fixed' does not take the option 'wokers'; its options: "
                                    "frac_bits, payload_bits, packet_events, fuse, workers"),
    ("{name: fixed,\n          fuse: 3}", 1, "backend: fixed: fuse: expected true or false, got 3"),
    ("{name: float, workers: -3}", 0, "backend: float: workers must be a whole number of workers"),
])
def test_a_specs_backend_options_are_checked_as_it_is_read_naming_its_line(tmp_path, backend, line, message):
    """Before, a misspelt option or a bad value said so only when the run started, naming no file (and fuse: 3
    ran as true)."""
    from tofnet.api import load_network
    path = tmp_path / "net.yaml"
    path.write_text(PAPER.replace("compile: {patch: [30, 30], budget: loihi2}", f"backend: {backend}"))
    at = PAPER.splitlines().index("compile: {patch: [30, 30], budget: loihi2}") + 1 + line
    with pytest.raises(SpecError) as err:
        load_network(path)
    assert str(err.value).startswith(f"{path}:{at}: {message}"), str(err.value)
    # a backend this install cannot run (lava on Python 3.11) is checked by its options' names only: the run
    # may ask for another
    path.write_text(PAPER.replace("compile: {patch: [30, 30], budget: loihi2}", "backend: {name: lava, packet_events: 4096}"))
    assert load_network(path)[2:] == ("lava", {"packet_events": 4096})


def test_units_as_strings_or_si_numbers():
    spec = load_spec(PAPER.replace("timestep: 1ms", "timestep: 1e-3").replace("max_depth: 20", "max_depth: 2000cm"))
    assert spec.network.process("input").timestep == 0.001
    assert spec.network.process("depth").max_depth == 20.0
    assert load_spec(PAPER.replace("[240, 180]", "240x180")).network.sensor_size == (240, 180)
    assert load_spec(PAPER.replace("type: DepthProcess", "type: Depth")).network.process("depth").max_depth == 20


def test_budget_files_and_names(tmp_path):
    assert load_budget("kapoho-point").max_chips == 8
    bare = tmp_path / "bare.yaml"
    bare.write_text("core: {accumulators: 2048}\nmax_chips: 2\n")
    assert (load_budget(bare).core.accumulators, load_budget(bare).max_chips) == (2048, 2)
    wrapped = tmp_path / "wrapped.yaml"
    wrapped.write_text("budget:\n  chip: {cores: 16}\n")
    assert load_budget(wrapped).chip.cores == 16
    spec_file = tmp_path / "spec.yaml"
    spec_file.write_text(PAPER.replace("budget: loihi2", "budget: oheo-gulch"))
    assert load_budget(spec_file).max_chips == 1
    bad = tmp_path / "bad.yaml"
    bad.write_text("core:\n  accumulators: 2048\n  neurons: many\n")
    with pytest.raises(SpecError, match=r"bad.yaml:3: budget.core.neurons: expected a positive whole number"):
        load_budget(bad)


# ---------------------------------------------------------------- errors name file, line and key

def error_of(text: str, tmp_path=None) -> str:
    with pytest.raises(SpecError) as err:
        load_spec(text)
    return str(err.value)


@pytest.mark.parametrize("old, new, expected", [
    ("counter_bits: 8}", "counter_bits: 8", r"<string>:\d+: malformed YAML: .*\(column \d+\)"),
    ("type: TimeOfTravelProcess", "type: TimeOfTrvel", r"<string>:4: processes.time_of_travel.type: unknown process "
                                                        r"type 'TimeOfTrvel'; expected one of .*TimeOfTravelProcess"),
    ("distance: 1", "distanse: 1", r"<string>:4: processes.time_of_travel.distanse: unknown parameter of "
                                   r"TimeOfTravelProcess; expected sensor_size, distance, counter_bits"),
    ("distance: 1", "distance: 0", r"<string>:4: processes.time_of_travel.distance: expected at least 1 px, got 0"),
    ("timestep: 1ms", "timestep: 1 fortnight", r"<string>:3: processes.input.timestep: expected a number or a "
                                               r"string like '1s'"),
    ("max_depth: 20", "max_depth: 0.01", r"<string>:5: processes.depth: depth: min_depth \(0.05 m\) must be below"),
    ("  - time_of_travel.counts -> depth.counts", "  - time_of_travel.counts => depth.counts",
     r"<string>:9: connections\[1\]: expected 'process.port -> process.port'"),
    ("  - time_of_travel.counts -> depth.counts", "  - time_of_travel.counts -> deep.counts",
     r"<string>:9: connections\[1\]: unknown process 'deep'; processes: input, time_of_travel, depth, velocity"),
    ("  - time_of_travel.counts -> depth.counts", "  - time_of_travel.count -> depth.counts",
     r"<string>:9: connections\[1\]: unknown port 'count' of time_of_travel \(TimeOfTravelProcess\); ports: "
     r"events, counts"),
    ("  - time_of_travel.counts -> depth.counts", "  - depth.counts -> time_of_travel.counts",
     r"<string>:9: connections\[1\]: .*a connection goes from an output port to an input port"),
    ("  - time_of_travel.counts -> depth.counts", "  - input.events -> depth.counts",
     r"<string>:9: connections\[1\]: cannot connect input.events \(polarity\) to depth.counts"),
    ("  - velocity.a_t -> depth.a_t\n", "",
     r"<string>:5: processes.depth: input depth.a_t is not connected"),
    ("compile: {patch: [30, 30], budget: loihi2}", "compile: {patch: [30, 30], budget: loihi9}",
     r"<string>:11: compile.budget: unknown budget 'loihi9'"),
    ("compile: {patch: [30, 30], budget: loihi2}", "compile:\n  patch: 30x30\n  budget:\n    core: {neurons: -4}",
     r"<string>:14: compile.budget.core.neurons: expected a positive whole number, got -4"),
    ("compile: {patch: [30, 30], budget: loihi2}", "compile:\n  patch: 0",
     r"<string>:12: compile.patch: expected auto"),
    ("compile: {patch: [30, 30], budget: loihi2}", "compile:\n  patch: {velocity: 30x30}",
     r"<string>:12: compile.patch.velocity: no core-placed process"),
    ("compile: {patch: [30, 30], budget: loihi2}", "compile: {patches: 30}",
     r"<string>:11: compile.patches: unknown key; expected patch, budget"),
    ("name: paper", "nmae: paper", r"<string>:1: nmae: unknown key; expected one of name, description, processes"),
    ("  depth:          {type: DepthProcess, min_depth: 0.05, max_depth: 20}",
     "  depth:          {min_depth: 0.05, max_depth: 20}", r"<string>:5: processes.depth: missing type"),
    ("  depth:          {type: DepthProcess, min_depth: 0.05, max_depth: 20}",
     "  depth:          {type: DepthProcess, min_depth: 0.05, min_depth: 20}",
     r"<string>:5: duplicate key 'min_depth'"),
    ("  depth:          {type: DepthProcess, min_depth: 0.05, max_depth: 20}",
     "  depth:          DepthProcess", r"<string>:5: processes.depth: expected a mapping with type"),
    ("  - input.events -> time_of_travel.events\n", "",
     r"<string>:4: processes.time_of_travel: input time_of_travel.events is not connected"),
])
def test_errors_name_the_line_and_key(old, new, expected):
    assert old in PAPER
    message = error_of(PAPER.replace(old, new))
    assert __import__("re").search(expected, message), message


def test_errors_name_the_file(tmp_path):
    path = tmp_path / "net.yaml"
    path.write_text(PAPER.replace("distance: 1", "distance: -1"))
    with pytest.raises(SpecError, match=rf"^{path}:4: processes.time_of_travel.distance"):
        load_spec(path)
    with pytest.raises(SpecError, match=rf"^{path}:4: processes.time_of_travel.distance"):
        load_spec(str(path))
    with pytest.raises(SpecError, match="missing.yaml: cannot read the spec"):
        load_spec(str(tmp_path / "missing.yaml"))
    with pytest.raises(SpecError, match="empty spec"):
        load_spec("\n\n")
    with pytest.raises(SpecError, match="<string>:1: expected a mapping") as err:
        load_spec("- just\n- a list\n")
    assert str(err.value).endswith("; got a list")  # in a user's words, not the YAML loader's class '_Seq'
    with pytest.raises(SpecError, match=r"expected a mapping with keys .*; got text$"):
        load_spec("just words\n")


def test_malformed_yaml_reports_yamls_line():
    message = error_of("name: x\nprocesses:\n  input: {type: InputProcess\n  depth: [\n")
    assert message.startswith("<string>:") and "malformed YAML" in message
    assert int(message.split(":")[1]) in (3, 4, 5)
