"""Latency is declared per output port: results, the summary, --json and batch rows give each output's."""

import numpy as np
import pytest

from tofnet import InputProcess, Network, Process
from tofnet.backends.event_driven import FixedBackend
from tofnet.backends.registry import available_backends, get_backend
from tofnet.cli.run_summary import latency_lines
from tofnet.core.ports import Payload, PortSpec
from tofnet.errors import NetworkError
from tofnet.models import StepModel, register_model
from tofnet.networks import depth_network
from tofnet.processes import TimeSurfaceProcess, VelocityProcess
from tofnet.io.recording import Recording
from tofnet.testing import TEST_INTRINSICS, moving_pattern

SENSOR = (24, 16)
CONSTANT = {"source": "constant", "velocity": [-0.5, 0.2, 0.1]}


def texture() -> Recording:
    return Recording(moving_pattern(SENSOR, (300, -150), 100_000, seed=1), intrinsics=TEST_INTRINSICS)


class Split(Process):
    """Test process: the spikes it receives, on ``now`` at once and on ``later`` two steps after."""

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes"),)
    outports = (PortSpec("now", Payload.POLARITY, 1, "the spikes", required=False),
                PortSpec("later", Payload.POLARITY, 1, "the spikes, two steps later", required=False,
                         added_latency_steps=2))
    placement = "host"


class SplitModel(StepModel):
    def __init__(self, process, ctx):
        super().__init__(process, ctx)
        self.held: dict[int, np.ndarray] = {}

    def step(self, k, inbox):
        spikes = inbox.get("events")
        if spikes is not None:
            self.held[k + 2] = np.array(spikes)
        return {"now": None if spikes is None else np.array(spikes), "later": self.held.pop(k, None)}


register_model(Split, ("reference", "float", "fixed"), SplitModel)


@pytest.mark.parametrize("name", available_backends())
def test_two_outputs_of_one_process_have_their_own_latency(name):
    inp = InputProcess(name="input", sensor_size=SENSOR, refractory=0)
    split, again = Split(name="split"), Split(name="again")  # ``again``: fed by split.later
    inp.events.connect(split.events)
    split.later.connect(again.events)
    recording = texture()
    result = get_backend(name).run(Network([inp, split, again]), recording, probes=["input.events", "split.later"])
    assert result.latency == {"split.now": 1, "again.now": 4, "again.later": 6, "input.events": 0, "split.later": 3}
    spikes = result.outputs["input.events"]
    assert len(spikes) > 100
    for output, steps in result.latency.items():  # every spike comes out on each output exactly that much later
        assert result.outputs[output]["step"].tolist() == (spikes["step"] + steps).tolist(), output
    assert set(latency_lines(result.summary())) == {
        "latency        1 step (1 ms)  split.now", "latency        4 steps (4 ms)  again.now",
        "latency        6 steps (6 ms)  again.later",
        "latency        0 steps (0 ms)  input.events", "latency        3 steps (3 ms)  split.later"}


def test_a_port_without_a_declaration_takes_the_process_latency_and_declarations_are_checked():
    assert TimeSurfaceProcess.port_latency_steps("depth") == TimeSurfaceProcess.added_latency_steps == 1
    assert Split.port_latency_steps("now") == 0 and Split.port_latency_steps("later") == 2
    assert Split(name="s").later.added_latency_steps == 2
    with pytest.raises(NetworkError, match="no output port 'events'"):
        Split.port_latency_steps("events")
    for wrong in (-1, 1.5, True):
        with pytest.raises(TypeError, match="added_latency_steps"):
            type("Wrong", (Process,), {"outports": (PortSpec("out", Payload.POLARITY, added_latency_steps=wrong),)})
    with pytest.raises(TypeError, match="on output ports"):
        type("Wrong", (Process,), {"inports": (PortSpec("events", Payload.POLARITY, added_latency_steps=1),)})


def paper_and_time_surface() -> Network:
    paper = depth_network(SENSOR, velocity=CONSTANT)
    surface = TimeSurfaceProcess(name="surface", sensor_size=SENSOR)
    velocity = VelocityProcess(name="surface_velocity", per="pixel", **CONSTANT)
    velocity.a_t.connect(surface.a_t)
    return Network([*paper.processes, surface, velocity], name="both")


def test_the_paper_network_beside_the_time_surface_estimator_gives_each_output_its_latency():
    recording = texture()
    result = FixedBackend().run(paper_and_time_surface(), recording)
    assert result.latency == {"depth.depth": 2, "surface.depth": 1, "surface.quality": 1}
    summary = result.summary()
    assert summary["latency"] == result.latency and summary["latency_steps"] == 2  # --json: both
    assert latency_lines(summary) == ["latency        2 steps (2 ms)  depth.depth",
                                      "latency        1 step (1 ms)  surface.depth",
                                      "latency        1 step (1 ms)  surface.quality"]


def test_the_fused_chain_takes_its_latency_from_the_declarations():
    recording = texture()
    net = depth_network(SENSOR, velocity=CONSTANT)
    fused = FixedBackend().run(net, recording, record_tot=True)
    unfused = FixedBackend(fuse=False).run(net, recording, record_tot=True)
    assert fused.latency == unfused.latency == {"depth.depth": 2, "time_of_travel.counts": 1}


def test_the_summary_s_seconds_are_the_clock_s_microseconds_converted_once():
    """A 7 ms step is 0.007 s in the summary (``seconds_of``, as the models and the fused path),
    not ``7000 * 1e-6`` = 0.006999999999999999."""
    net = depth_network(SENSOR, input={"timestep": "7ms"}, velocity=CONSTANT)
    summary = FixedBackend().run(net, texture()).summary()
    assert (summary["timestep_s"], summary["latency_steps"], summary["latency_s"]) == (0.007, 2, 0.014)
