"""The event-driven backends (`float`, `fixed`): equal to the reference, streaming, counts."""

import numpy as np
import pytest

from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.backends.reference import ReferenceBackend
from tofnet.errors import BackendError
from tofnet.events import EVENT_DTYPE, make_events
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording
from tofnet.networks import depth_network

INTRINSICS = Intrinsics(200.0, 210.0, 19.5, 14.5)


def random_recording(seed=1, sensor=(40, 30), n=30_000, duration_us=200_000):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(5_000, 5_000 + duration_us, n))
    events = make_events(t, rng.integers(0, sensor[0] + 2, n), rng.integers(0, sensor[1], n), rng.integers(0, 2, n))
    return Recording(events, intrinsics=INTRINSICS)


def scene(per="patch", update_every=1, distance=1, counter_bits=6, sensor=(40, 30)):
    return depth_network(sensor, input={"refractory": "2ms"},
                         time_of_travel={"distance": distance, "counter_bits": counter_bits},
                         velocity={"source": "constant", "velocity": [-0.4, 0.2, 0.3], "per": per,
                                   "patch_size": 7, "update_every": update_every})


def canonical(depth):
    return np.sort(depth, order=["step", "y", "x"])


@pytest.mark.parametrize("per,update_every,distance", [("pixel", 1, 1), ("patch", 3, 2), ("patch", 1, 1)])
def test_float_equals_the_reference_backend(per, update_every, distance):
    net, recording = scene(per, update_every, distance), random_recording()
    ref = ReferenceBackend().run(net, recording, record_tot=True)
    flt = FloatBackend(packet_events=4321).run(net, recording, record_tot=True)
    a, b = canonical(ref.depth), canonical(flt.depth)
    assert len(a) > 1000
    assert np.array_equal(a[["t", "x", "y", "step"]], b[["t", "x", "y", "step"]])
    assert np.allclose(a["z"], b["z"], rtol=1e-12, atol=0)
    order = ["step", "y", "x", "direction"]
    assert np.array_equal(np.sort(ref.tot, order=order), np.sort(flt.tot, order=order))
    for field in ("events_in", "accepted", "dropped", "rejected", "tot_spikes", "steps", "t0_us",
                  "timestep_us", "latency_steps"):
        assert getattr(flt, field) == getattr(ref, field), field


@pytest.mark.parametrize("fuse", [True, False])
@pytest.mark.parametrize("backend", [FloatBackend, FixedBackend])
def test_a_stream_fed_in_packets_equals_a_run(backend, fuse):
    net, recording = scene(), random_recording(seed=4)
    whole = backend().run(net, recording, record_tot=True)
    stream = backend(fuse=fuse).open_stream(net, intrinsics=INTRINSICS,
                                            velocity_source=ConstantVelocity((-0.4, 0.2, 0.3)), record_tot=True)
    rng = np.random.default_rng(0)
    cuts = np.sort(rng.choice(len(recording.events), 25, replace=False))
    depth, tot = [], []
    for lo, hi in zip(np.r_[0, 0, cuts], np.r_[0, cuts, len(recording.events)]):  # includes an empty packet
        out = stream.feed_all(recording.events[lo:hi])
        depth.append(out.get("depth.depth", whole.depth[:0]))
        tot.append(out.get("time_of_travel.counts", whole.tot[:0]))
    closed = stream.close()
    depth.append(closed.depth)
    tot.append(closed.tot)
    # a step split over packets comes out once complete: the packets' outputs join to the run's
    assert np.concatenate(depth).tobytes() == whole.depth.tobytes()
    assert np.concatenate(tot).tobytes() == whole.tot.tobytes()
    assert closed.backend == backend.name
    for field in ("events_in", "accepted", "dropped", "rejected", "tot_spikes", "steps", "t0_us"):
        assert getattr(closed, field) == getattr(whole, field), field
    with pytest.raises(BackendError, match="closed"):
        stream.feed(recording.events[:1])


@pytest.mark.parametrize("fuse", [True, False])
def test_a_stream_returns_the_steps_a_later_event_or_until_us_completed(fuse):
    net, recording = scene(), random_recording(seed=5)
    whole = FixedBackend().run(net, recording)
    stream = FixedBackend(fuse=fuse).open_stream(net, intrinsics=INTRINSICS,
                                                 velocity_source=ConstantVelocity((-0.4, 0.2, 0.3)))
    events = recording.events
    t0 = int(events["t"][0])  # step 0 starts at the first event, as in the run
    middle, end = np.searchsorted(events["t"], [t0 + 120_500, t0 + 121_000])
    depth = stream.feed_all(events[:middle])["depth.depth"]  # the last event's step (120) may get more events
    assert depth["step"].max() == 119  # as on the chip: the steps that ran, fused or not
    # the rest of step 120, and the promise that nothing before step 121 is left
    late = stream.feed_all(events[middle:end], until_us=t0 + 121_000)["depth.depth"]
    assert set(late["step"].tolist()) == {120}
    assert np.concatenate([depth, late]).tobytes() == whole.depth[whole.depth["step"] <= 120].tobytes()


def test_stream_start_time_is_the_pipeline_t0_else_the_first_event():
    events = make_events([7_300, 12_300], [0, 1], [0, 0], [1, 1])
    source = ConstantVelocity((-0.5, 0.0, 0.0))
    net = depth_network((2, 1), input={"refractory": 0},
                        velocity={"source": "constant", "velocity": [-0.5, 0, 0], "per": "pixel"})
    stream = FixedBackend().open_stream(net, intrinsics=INTRINSICS, velocity_source=source)
    (estimate,) = stream.feed(events)
    assert estimate["step"] == 7 and estimate["t"] == 7_300 + 8_000  # t0 = first event
    stream = FixedBackend().open_stream(net, intrinsics=INTRINSICS, velocity_source=source, t0_us=5_000)
    (estimate,) = stream.feed(events)
    assert estimate["step"] == 9 and estimate["t"] == 5_000 + 10_000  # steps 2 and 7 -> depth step 9


def test_progress_is_reported_per_packet():
    calls = []
    net, recording = scene(), random_recording(n=10_000)
    FixedBackend(packet_events=3000).run(net, recording, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(3000, 10_000), (6000, 10_000), (9000, 10_000), (10_000, 10_000)]


def test_every_event_is_accounted_for_and_an_empty_recording_runs():
    net, recording = scene(), random_recording(seed=9)
    result = FixedBackend().run(net, recording)
    assert result.events_in == len(recording.events) == result.accepted + sum(result.dropped.values())
    assert result.dropped["out_of_bounds"] > 0 and result.dropped["refractory"] > 0
    assert result.latency_steps == 2 and result.timestep_us == 1000
    empty = FixedBackend().run(net, Recording(np.empty(0, EVENT_DTYPE), intrinsics=INTRINSICS))
    assert empty.events_in == 0 and len(empty.depth) == 0 and empty.steps == 2


def test_sparse_recordings_split_the_velocity_table():
    # Two bursts ten minutes apart at 1 ms steps: the table is computed per burst, not for 600k steps.
    a = make_events([1_000, 6_000], [0, 1], [0, 0], [1, 1])
    b = make_events([600_001_000, 600_006_000], [0, 1], [0, 0], [1, 1])
    net = depth_network((2, 1), input={"refractory": 0},
                        velocity={"source": "constant", "velocity": [-0.5, 0, 0], "per": "pixel"})
    recording = Recording(np.concatenate([a, b]), intrinsics=Intrinsics(200.0, 200.0, 0.0, 0.0))
    result = FixedBackend().run(net, recording)
    assert result.depth["step"].tolist() == [7, 600_007] and result.depth["z"] == pytest.approx(0.5, rel=1e-4)


def test_unsorted_events_are_refused():
    events = make_events([5_000, 1_000], [0, 1], [0, 0], [1, 1])
    net = depth_network((2, 1), input={"refractory": 0, "t0": 0},
                        velocity={"source": "constant", "velocity": [-0.5, 0, 0]})
    with pytest.raises(BackendError, match="not sorted"):
        FixedBackend().run(net, Recording(events, intrinsics=INTRINSICS))


def test_backend_names_and_arithmetic():
    assert (FixedBackend.name, FixedBackend.arithmetic) == ("fixed", "fixed")
    assert (FloatBackend.name, FloatBackend.arithmetic) == ("float", "float")
    assert FixedBackend(frac_bits=12, payload_bits=20).format.max_value == pytest.approx(128.0, abs=1e-3)
    with pytest.raises(BackendError):
        FixedBackend(packet_events=0)
