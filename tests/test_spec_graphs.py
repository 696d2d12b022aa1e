"""YAML specs for any graph: every shape round-trips, user process types load by module path or entry point."""

import pytest

from tofnet.errors import SpecError
from tofnet.io import spec as spec_module
from tofnet.io.spec import dump_spec, load_spec, networks_equal, spec_from_dict
from tofnet.networks import denoised_network, depth_network, multi_distance_network


def user_network():
    from tofnet import DepthProcess, InputProcess, Network, TimeOfTravelProcess, VelocityProcess
    from tofnet.testing import ParityGateProcess
    inp, gate = InputProcess(name="input", sensor_size=(40, 30)), ParityGateProcess(name="gate", parity=1)
    tot, dep, vel = TimeOfTravelProcess(name="tot", distance=2), DepthProcess(name="depth"), VelocityProcess()
    inp.events.connect(gate.events)
    gate.passed.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    return Network([inp, gate, tot, dep, vel], name="user")


@pytest.mark.parametrize("build", [
    lambda: depth_network((64, 48)),
    lambda: multi_distance_network((64, 48), (1, 2, 3)),
    lambda: denoised_network((64, 48), denoise={"radius": 2, "window": "12ms"}),
    user_network,
], ids=["paper", "three-distances", "denoised", "user-process"])
def test_every_graph_round_trips(build):
    network = build()
    for full in (False, True):
        again = load_spec(dump_spec(network, full=full)).network
        assert networks_equal(again, network)


def test_a_user_process_is_written_and_read_by_module_path():
    text = dump_spec(user_network())
    assert "type: 'tofnet.testing:ParityGateProcess'" in text
    loaded = load_spec(text).network
    assert type(loaded.process("gate")).__name__ == "ParityGateProcess" and loaded.process("gate").parity == 1


def test_bad_module_paths_get_one_line_naming_the_key():
    body = {"processes": {"x": {"type": "no_such_module_xyz:Thing"}}}
    with pytest.raises(SpecError, match=r"processes\.x\.type: cannot import 'no_such_module_xyz'"):
        spec_from_dict(body, allow_import=["no_such_module_xyz"])
    for type_name in ("tofnet.networks:depth_network", "tofnet:Process"):  # the base class: no port, no model
        with pytest.raises(SpecError, match=f"'{type_name}' is not a process type"):
            spec_from_dict({"processes": {"x": {"type": type_name}}})
    body = {"processes": {"x": {"type": "tofnet.testing:ParityGateProces"}}}  # a typo
    with pytest.raises(SpecError, match="module 'tofnet.testing' has no 'ParityGateProces'"):
        spec_from_dict(body)


def test_a_bare_type_name_two_modules_define_is_refused_naming_both(monkeypatch):
    """The last class imported used to win, silently."""
    import sys
    import types

    from tofnet.core.process import Process
    monkeypatch.setattr(Process, "_registry", dict(Process._registry))
    monkeypatch.setattr(Process, "_defined", {name: dict(where) for name, where in Process._defined.items()})
    for name in ("twin_a_zz", "twin_b_zz"):
        module = types.ModuleType(name)
        exec("from tofnet.testing import ParityGateProcess\n"
             "class TwinGateProcess(ParityGateProcess):\n    pass\n", module.__dict__)
        monkeypatch.setitem(sys.modules, name, module)
    text = ("processes:\n  input: {type: InputProcess, sensor_size: [10, 8]}\n  gate: {type: TwinGate}\n"
            "connections:\n  - input.events -> gate.events\n")
    with pytest.raises(SpecError, match="'TwinGateProcess' is defined by twin_a_zz:TwinGateProcess and "
                                        "twin_b_zz:TwinGateProcess; name one as module:Class"):
        load_spec(text)
    named = load_spec(text.replace("TwinGate}", "'twin_b_zz:TwinGateProcess'}"), allow_import=["twin_b_zz"])
    assert type(named.network.process("gate")).__module__ == "twin_b_zz"

    def local_class():  # made inside a function: no spec can name it by module, so it makes nothing ambiguous
        from tofnet.testing import ParityGateProcess

        class SpikeTallyProcess(ParityGateProcess):
            pass
        return SpikeTallyProcess
    local_class()
    assert Process.ambiguity("SpikeTallyProcess") is None
    # a user's class named as a built-in: specs tofnet writes name the built-in by module, and load
    module = types.ModuleType("twin_c_zz")
    exec("from tofnet.processes.depth import DepthProcess as Base\nclass DepthProcess(Base):\n    pass\n",
         module.__dict__)
    monkeypatch.setitem(sys.modules, "twin_c_zz", module)
    text = dump_spec(depth_network((64, 48)))
    assert "type: 'tofnet.processes.depth:DepthProcess'" in text
    assert type(load_spec(text).network.process("depth")).__module__ == "tofnet.processes.depth"


def test_an_entry_point_offers_a_process_type(monkeypatch):
    class EntryPoint:
        name = "ParityGate2"

        def load(self):
            from tofnet.testing import ParityGateProcess
            return ParityGateProcess

    monkeypatch.setattr(spec_module, "entry_points", lambda group: [EntryPoint()] if group == "tofnet.processes" else [])
    text = ("processes:\n  input: {type: InputProcess, sensor_size: [10, 8]}\n  gate: {type: ParityGate2}\n"
            "connections:\n  - input.events -> gate.events\n")
    assert type(load_spec(text).network.process("gate")).__name__ == "ParityGateProcess"
