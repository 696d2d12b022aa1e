"""Any process graph runs on every backend: composition, models, latency, probes, fan-in, streams."""

import contextlib

import numpy as np
import pytest

from tofnet import DepthProcess, InputProcess, Network, Process, TimeOfTravelProcess, VelocityProcess
from tofnet.backends.event_driven import FixedBackend
from tofnet.backends.fusion import FusedStream
from tofnet.backends.graph import canonical
from tofnet.backends.registry import available_backends, get_backend
from tofnet.backends.stream import GraphStream
from tofnet.compiler import compile_network
from tofnet.conformance import BackendRunner
from tofnet.core.ports import Payload, PortSpec
from tofnet.errors import BackendError, NetworkError
from tofnet.io.recording import Recording
from tofnet.models import StepModel, register_model
from tofnet.networks import denoised_network, depth_network, multi_distance_network
from tofnet.testing import TEST_INTRINSICS, merge_events, moving_pattern, noise_events

SENSOR = (24, 16)
VELOCITY = {"source": "constant", "velocity": [-0.5, 0.2, 0.1], "per": "pixel"}


def texture(seed=1, noise=0.0):
    parts = [moving_pattern(SENSOR, (300, -150), 150_000, seed=seed)]
    if noise:
        parts.append(noise_events(SENSOR, noise, 150_000, seed=seed + 1))
    return Recording(merge_events(*parts), intrinsics=TEST_INTRINSICS)


@pytest.fixture(scope="module", params=available_backends())
def backend(request):
    with contextlib.ExitStack() as stack:
        yield BackendRunner(get_backend(request.param), stack)


def test_composition_does_not_change_semantics(backend):
    """The distance-1 branch of a two-distance network gives exactly the paper network's depth."""
    recording = texture()
    two = compile_network(multi_distance_network(SENSOR, (1, 2), input={"refractory": 0}, velocity=VELOCITY),
                          patch=(8, 8))
    both = backend.run(two, recording, record_tot=True)
    alone = FixedBackend().run(depth_network(SENSOR, input={"refractory": 0}, velocity=VELOCITY), recording)
    if backend.arithmetic == "fixed":
        assert both.outputs["depth1.depth"].tobytes() == alone.depth.tobytes()
    else:
        assert np.array_equal(both.outputs["depth1.depth"][["step", "x", "y"]], alone.depth[["step", "x", "y"]])
    assert len(both.outputs["depth2.depth"]) > 100 and both.latency["depth2.depth"] == 2
    assert set(both.counts) == {"input", "tot1", "depth1", "tot2", "depth2", "velocity"}
    assert both.counts["tot1"]["spikes"] == len(both.outputs["tot1.counts"])
    with pytest.raises(BackendError, match="2 depth outputs"):
        both.depth


def test_a_filter_between_input_and_units_adds_a_step_of_latency(backend):
    net = denoised_network(SENSOR, input={"refractory": "1ms"}, denoise={"window": "4ms"}, velocity=VELOCITY)
    result = backend.run(compile_network(net, patch=(8, 8)), texture(noise=30.0), record_tot=True)
    assert result.latency_steps == 3 and result.latency["time_of_travel.counts"] == 2
    assert result.counts["denoise"]["isolated"] > 50 and result.counts["denoise"]["passed"] > 1000
    stamps = result.t0_us + (result.depth["step"] + 1) * result.timestep_us
    assert np.array_equal(result.depth["t"], stamps) and result.depth["step"].min() >= 3


class Merge(Process):
    """Test process: several polarity sources into one port (fan-in), sent on unchanged."""

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes", fan_in=True),)
    outports = (PortSpec("merged", Payload.POLARITY, 1, "all of them", required=False),)
    placement = "host"


class Delay(Process):
    """Test process: sends what it receives (one more step of latency)."""

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes"),)
    outports = (PortSpec("out", Payload.POLARITY, 1, "the same spikes"),)
    placement = "host"


class PassOn(StepModel):
    def step(self, k, inbox):
        spikes = next(iter(inbox.values()))
        return {self.process.outports[0].name: None if spikes is None else np.array(spikes)}


register_model(Merge, ("reference", "float", "fixed"), PassOn)
register_model(Delay, ("reference", "float", "fixed"), PassOn)


def test_fan_in_joins_sources_in_canonical_order_and_latency_is_the_longest_path(backend):
    inp = InputProcess(name="input", sensor_size=SENSOR, refractory=0)
    delay, merge = Delay(name="delay"), Merge(name="merge")
    inp.events.connect(delay.events)
    inp.events.connect(merge.events)
    delay.out.connect(merge.events)
    recording = texture()
    result = backend.run(Network([inp, delay, merge]), recording, probes=["input.events"])
    spikes, merged = result.outputs["input.events"], result.outputs["merge.merged"]
    assert result.latency == {"merge.merged": 2, "input.events": 0}
    # every input spike arrives once directly (1 step later) and once through the delay (2 steps later)
    expected = np.concatenate([spikes, spikes])
    expected["step"] = np.concatenate([spikes["step"] + 1, spikes["step"] + 2])
    assert merged.tobytes() == canonical(expected[np.argsort(expected["step"], kind="stable")]).tobytes()


def test_a_process_without_a_model_for_the_backend_fails_before_running():
    class Lonely(Process):
        inports = (PortSpec("events", Payload.POLARITY, 1, "spikes"),)
        outports = (PortSpec("out", Payload.POLARITY, 1, "spikes", required=False),)
        placement = "host"

    register_model(Lonely, "reference", PassOn)
    inp, lonely = InputProcess(name="input", sensor_size=SENSOR), Lonely(name="lonely")
    inp.events.connect(lonely.events)
    net = Network([inp, lonely])
    with pytest.raises(BackendError) as err:
        FixedBackend().run(net, texture())
    message = str(err.value)
    assert "'lonely' (Lonely) has no 'fixed' model" in message and "'fixed' backend" in message
    assert "reference (reference)" in message
    assert len(get_backend("reference").run(net, texture()).outputs["lonely.out"]) > 100


def test_probes_are_checked():
    net = depth_network(SENSOR, velocity=VELOCITY)
    with pytest.raises(NetworkError, match="an input port; probe the output feeding it"):
        FixedBackend().run(net, texture(), probes=["depth.counts"])
    with pytest.raises(NetworkError, match="has no port 'nope'"):
        FixedBackend().run(net, texture(), probes=["depth.nope"])


def test_one_clock_per_network():
    inp = InputProcess(name="input", sensor_size=SENSOR, timestep="1ms")
    other = InputProcess(name="other", sensor_size=SENSOR, timestep="2ms")
    merge = Merge(name="merge")
    inp.events.connect(merge.events)
    other.events.connect(merge.events)
    with pytest.raises(NetworkError, match="disagree on timestep"):
        FixedBackend().run(Network([inp, other, merge]), texture())


@pytest.mark.parametrize("name", ["reference", "float", "fixed"])
def test_a_stream_of_any_graph_equals_a_run(name):
    net = denoised_network(SENSOR, input={"refractory": "1ms", "t0": 0}, denoise={"window": "4ms"},
                           velocity=VELOCITY)
    recording = texture(noise=30.0)
    whole = get_backend(name).run(net, recording, probes=["denoise.passed"])
    stream = get_backend(name).open_stream(net, recording=recording, probes=["denoise.passed"])
    assert isinstance(stream, GraphStream)
    bounds = np.searchsorted(recording.events["t"], np.arange(0, 160_000, 7_300))
    parts = [stream.feed_all(recording.events[lo:hi]) for lo, hi in zip(bounds[:-1], bounds[1:])]
    parts.append(stream.close().outputs)
    for key in whole.outputs:
        joined = np.concatenate([p[key] for p in parts if key in p])
        assert joined.tobytes() == whole.outputs[key].tobytes()  # packets end between steps: canonical as is


def test_a_stream_returns_complete_steps_as_soon_as_it_knows_they_are():
    net = denoised_network(SENSOR, input={"refractory": 0, "t0": 0}, denoise={"window": "4ms"}, velocity=VELOCITY)
    stream = FixedBackend().open_stream(net, intrinsics=TEST_INTRINSICS, probes=["denoise.passed"])
    events = texture().events
    early = events[events["t"] < 20_000]
    out = stream.feed_all(early)  # step 19 (19-20 ms) may still get events: steps 0-18 run
    assert out["denoise.passed"]["step"].max() == 18  # what arrived by step 18
    out = stream.feed_all(events[:0], until_us=20_000)  # nothing before 20 ms is left to come: step 19 runs
    assert out["denoise.passed"]["step"].tolist() == [19] * len(out["denoise.passed"])
    with pytest.raises(BackendError, match="not sorted"):
        stream.feed_all(early[-3:])


def test_the_paper_chain_is_fused_whatever_its_names():
    inp = InputProcess(name="camera", sensor_size=SENSOR)
    tot, dep = TimeOfTravelProcess(name="units"), DepthProcess(name="neurons")
    vel = VelocityProcess(name="ego", **VELOCITY)
    inp.events.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    net = Network([vel, dep, inp, tot])
    assert isinstance(FixedBackend().open_stream(net, intrinsics=TEST_INTRINSICS), FusedStream)
    assert isinstance(FixedBackend(fuse=False).open_stream(net, intrinsics=TEST_INTRINSICS), GraphStream)
    assert isinstance(get_backend("reference").open_stream(net, intrinsics=TEST_INTRINSICS), GraphStream)

    class MyDepth(DepthProcess):  # a subclass may behave differently: it runs unfused, on DepthProcess's models
        pass
    inp, tot, dep = InputProcess(name="input", sensor_size=SENSOR), TimeOfTravelProcess(), MyDepth(name="depth")
    vel = VelocityProcess(**VELOCITY)
    inp.events.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    sub = Network([inp, tot, dep, vel])
    assert isinstance(FixedBackend().open_stream(sub, intrinsics=TEST_INTRINSICS), GraphStream)
    recording = texture()
    assert FixedBackend().run(sub, recording).depth.tobytes() == FixedBackend().run(net, recording).depth.tobytes()


def test_an_executor_of_the_fixed_family_computes_in_the_fixed_backends_format():
    """``GraphExecutor(family="fixed")`` without a ``fixed_format`` computed the depth in float (z 0.75 where the
    fixed backend gave 0.74996948): it now takes the fixed backend's format."""
    from tofnet.backends.graph import GraphExecutor
    from tofnet.backends.runtime import clock_of, start_time_us
    from tofnet.conformance.cases import get_case

    scene = get_case("patch-d2-ragged").build()
    clock = clock_of(scene.network)
    executor = GraphExecutor(scene.network, family="fixed", backend="mine", recording=scene.recording,
                             t0_us=start_time_us(clock.t0_us, scene.recording), timestep_us=clock.timestep_us)
    executor.feed(scene.recording.events)
    depth = executor.advance(executor.complete_until() + 1 + executor.drain_steps)["depth.depth"]
    fixed = FixedBackend().run(scene.network, scene.recording).depth
    assert len(depth) > 100 and depth.tobytes() == fixed.tobytes()
