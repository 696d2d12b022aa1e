"""The process-graph core: ports, parameters, network validation and its error messages."""

import pytest

from tofnet import DepthProcess, InputProcess, Network, TimeOfTravelProcess, VelocityProcess, depth_network
from tofnet.core import Param, PortSpec, Process
from tofnet.core.ports import Payload
from tofnet.errors import NetworkError


def chain():
    inp = InputProcess(sensor_size=(32, 24))
    tot = TimeOfTravelProcess()
    dep = DepthProcess()
    vel = VelocityProcess(source="constant", velocity=[0.5, 0, 0])
    return inp, tot, dep, vel


def test_connected_network_propagates_the_sensor_size_to_every_process():
    inp, tot, dep, vel = chain()
    inp.events.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    net = Network([inp, tot, dep, vel])
    assert [p.sensor_size for p in net.processes] == [(32, 24)] * 4
    assert tot.counts.shape == (4, 24, 32) and dep.a_t.shape == (2, 24, 32)
    assert [p.name for p in net.topological_order()][0] in ("input", "velocity")
    assert net.graph.number_of_edges() == 3


def test_parameters_are_typed_with_units():
    inp = InputProcess(timestep="500us", refractory="2ms")
    assert inp.timestep == pytest.approx(5e-4) and inp.refractory == pytest.approx(2e-3)
    assert DepthProcess(max_depth="250cm").max_depth == pytest.approx(2.5)
    with pytest.raises(NetworkError, match=r"time_of_travel.distance: expected at least 1"):
        TimeOfTravelProcess(distance=0)
    with pytest.raises(NetworkError, match=r"input.timestep: expected a number or a string like '1s'"):
        InputProcess(timestep="fast")
    with pytest.raises(NetworkError, match=r"unknown parameter\(s\) distnce"):
        TimeOfTravelProcess(distnce=2)
    with pytest.raises(NetworkError, match="source 'constant' needs velocity"):
        VelocityProcess(source="constant")
    with pytest.raises(NetworkError, match="min_depth .* must be below max_depth"):
        DepthProcess(min_depth=3, max_depth=2)


def test_output_to_output_is_refused():
    inp, tot, dep, vel = chain()
    with pytest.raises(NetworkError, match="cannot connect output input.events to output time_of_travel.counts"):
        inp.events.connect(tot.counts)


def test_connecting_from_an_input_port_is_refused():
    inp, tot, dep, vel = chain()
    with pytest.raises(NetworkError, match="cannot connect from input time_of_travel.events"):
        tot.events.connect(inp.events)


def test_payload_kinds_must_match():
    inp, tot, dep, vel = chain()
    with pytest.raises(NetworkError, match="expects count"):
        inp.events.connect(dep.counts)


def test_an_input_takes_one_source():
    inp, tot, dep, vel = chain()
    other = InputProcess(name="other", sensor_size=(32, 24))
    inp.events.connect(tot.events)
    with pytest.raises(NetworkError, match="already connected to input.events"):
        other.events.connect(tot.events)


def test_unconnected_required_input_is_named():
    inp, tot, dep, vel = chain()
    inp.events.connect(tot.events)
    tot.counts.connect(dep.counts)
    with pytest.raises(NetworkError, match=r"input depth.a_t is not connected"):
        Network([inp, tot, dep, vel])


def test_shape_mismatch_names_both_ports():
    inp, tot, dep, vel = chain()
    tot = TimeOfTravelProcess(sensor_size=(16, 16))
    inp.events.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    with pytest.raises(NetworkError, match=r"shape mismatch: time_of_travel.events is 16x16 px but its source "
                                           r"input.events is 32x24 px"):
        Network([inp, tot, dep, vel])


def test_duplicate_names_are_refused():
    inp, tot, dep, vel = chain()
    with pytest.raises(NetworkError, match="two processes are named 'time_of_travel'"):
        Network([inp, tot, TimeOfTravelProcess(), dep, vel])


def test_processes_outside_the_network_are_named():
    inp, tot, dep, vel = chain()
    inp.events.connect(tot.events)
    with pytest.raises(NetworkError, match="time_of_travel.events, whose process is not in the network"):
        Network([inp])


class Relay(Process):
    """A test process that passes counts on, to build a cycle."""
    inports = (PortSpec("inp", Payload.COUNT, 4),)
    outports = (PortSpec("out", Payload.COUNT, 4, required=False),)
    params = (Param("gain", "int", 1),)


def test_cycles_are_refused_with_the_path():
    a, b = Relay(name="a", sensor_size=(4, 4)), Relay(name="b")
    a.out.connect(b.inp)
    b.out.connect(a.inp)
    with pytest.raises(NetworkError, match=r"has a cycle \((a -> b -> a|b -> a -> b)\)"):
        Network([a, b])


def test_a_port_and_a_parameter_cannot_share_a_name():
    with pytest.raises(TypeError, match="both a port and a parameter"):
        class Bad(Process):
            outports = (PortSpec("gain", Payload.COUNT, 1),)
            params = (Param("gain", "int", 1),)


def test_unknown_process_type_lists_the_known_ones():
    with pytest.raises(NetworkError, match="known types: .*TimeOfTravelProcess"):
        Process.type_named("TimeOfTraval")


def test_depth_network_builds_the_paper_graph():
    net = depth_network(time_of_travel={"distance": 2})
    assert net.sensor_size == (240, 180)
    assert net.process("time_of_travel").distance == 2
    assert {(s.qualified_name, d.qualified_name) for s, d in net.connections()} == {
        ("input.events", "time_of_travel.events"), ("time_of_travel.counts", "depth.counts"),
        ("velocity.a_t", "depth.a_t")}
