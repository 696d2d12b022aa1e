"""Streams of the event-driven backends: bounded memory, owned results, any packet split."""

import tracemalloc

import numpy as np

from tofnet.backends.graph import canonical
import pytest

from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.errors import BackendError
from tofnet.events import make_events
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording
from tofnet.networks import depth_network

SENSOR = (48, 36)
INTRINSICS = Intrinsics(200.0, 200.0, 23.5, 17.5)
VELOCITY = (-0.4, 0.2, 0.3)


def recording(duration_us, rate_per_us=0.5, seed=0):
    rng = np.random.default_rng(seed)
    n = int(duration_us * rate_per_us)
    t = np.sort(rng.integers(0, duration_us, n))
    return Recording(make_events(t, rng.integers(0, SENSOR[0], n), rng.integers(0, SENSOR[1], n),
                                 rng.integers(0, 2, n)), intrinsics=INTRINSICS)


def network():
    return depth_network(SENSOR, input={"refractory": "3ms"},
                         velocity={"source": "constant", "velocity": list(VELOCITY)})


def open_stream(backend=FixedBackend, record_tot=False, t0_us=0):
    return backend().open_stream(network(), intrinsics=INTRINSICS, velocity_source=ConstantVelocity(VELOCITY),
                                 t0_us=t0_us, record_tot=record_tot)


def packets_of(events, step_us=1000):
    bounds = np.searchsorted(events["t"], np.arange(0, int(events["t"][-1]) + step_us + 1, step_us))
    return [events[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]


def peak_while_streaming(packets):
    stream = open_stream()
    tracemalloc.start()
    for packet in packets:
        stream.feed(packet)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def test_a_streams_memory_does_not_grow_with_the_recording():
    packets = packets_of(recording(4_000_000).events)  # 4 s of 1 ms packets
    peak_while_streaming(packets[:10])  # loads the compiled kernel outside the measurement
    short, long = peak_while_streaming(packets[:200]), peak_while_streaming(packets)
    assert long < short + 64 * 1024, (short, long)  # the velocity look-ahead table is ~24 kB


@pytest.mark.parametrize("backend", [FixedBackend, FloatBackend])
def test_every_feed_returns_estimates_a_later_feed_leaves_alone(backend):
    events = recording(300_000).events
    stream = open_stream(backend, record_tot=True)
    kept, copies, tots = [], [], []
    for packet in packets_of(events):
        depth = stream.feed(packet)
        kept.append(depth)
        copies.append(depth.copy())
        tots.append((stream.tot, stream.tot.copy()))
    assert sum(len(d) for d in kept) > 1000
    assert all(np.array_equal(a, b) for a, b in zip(kept, copies))
    assert all(np.array_equal(a, b) for a, b in tots)


def test_single_event_packets_equal_one_run():
    rec = recording(60_000, seed=3)
    whole = FixedBackend().run(network(), rec, record_tot=True)
    stream = open_stream(record_tot=True, t0_us=None)  # the first event, as run
    depth, tot = [], []
    for i in range(len(rec.events)):
        depth.append(stream.feed(rec.events[i:i + 1]))
        tot.append(stream.tot)
    closed = stream.close()
    assert len(whole.depth) > 100
    assert np.array_equal(canonical(np.concatenate(depth)), whole.depth)
    assert np.array_equal(canonical(np.concatenate(tot)), whole.tot)
    assert (closed.accepted, closed.dropped, closed.rejected, closed.steps) == \
        (whole.accepted, whole.dropped, whole.rejected, whole.steps)


def test_a_packet_going_back_in_time_is_refused():
    events = recording(20_000, seed=4).events
    stream = open_stream()
    stream.feed(events[len(events) // 2:])
    with pytest.raises(BackendError, match="not sorted"):
        stream.feed(events[:len(events) // 2])


def fixed_stream(fuse: bool):
    """A fresh stream of the fixed backend, fused or model by model, at the test's constant velocity."""
    return FixedBackend(fuse=fuse).open_stream(network(), intrinsics=INTRINSICS,
                                               velocity_source=ConstantVelocity(VELOCITY), t0_us=0)


@pytest.mark.parametrize("fuse", [True, False])
def test_a_refused_packet_leaves_the_stream_as_it_was(fuse):
    """Issue 11: after a refusal the stream goes on exactly as if it never saw the packet."""
    events = recording(120_000, seed=5).events
    half = len(events) // 2

    def stream_of():
        return fixed_stream(fuse)
    clean = stream_of()
    expected = [clean.feed_all(events[:half]), clean.feed_all(events[half:])]
    expected_close = clean.close()
    stream = stream_of()
    got = [stream.feed_all(events[:half])]
    past = events[half - 400:half - 300].copy()  # ~90 ms in the past
    for bad in (past, events[half:][::-1], events[half:half + 10].astype([("t", "<i8"), ("x", "<i4"), ("y", "<i4"),
                                                                            ("p", "u1")])):
        with pytest.raises(BackendError, match="not sorted|dtype"):
            stream.feed_all(bad)
    with pytest.raises(BackendError, match="numpy array"):
        stream.feed_all(list(events[half:half + 3]))
    got.append(stream.feed_all(events[half:]))
    closed = stream.close()
    for a, b in zip(got, expected):
        assert a.keys() == b.keys() and all(a[k].tobytes() == b[k].tobytes() for k in a)
    assert closed.counts == expected_close.counts and closed.steps == expected_close.steps


@pytest.mark.parametrize("fuse", [True, False])
def test_a_polarity_other_than_0_or_1_is_refused_and_changes_nothing(fuse):
    """OFF recoded as 255 (an int8 -1 cast to uint8) ran as ON, with no message (357,486 estimates
    instead of 320,320 in the audit); refused with the writers' line, the stream going on as before."""
    events = recording(60_000, seed=8).events
    half = len(events) // 2

    def stream_of():
        return fixed_stream(fuse)
    clean = stream_of()
    expected = [clean.feed_all(events[:half]), clean.feed_all(events[half:])]
    stream = stream_of()
    got = [stream.feed_all(events[:half])]
    for value in (255, 2):
        bad = events[half:].copy()
        bad["p"][bad["p"] == 0] = value
        with pytest.raises(BackendError, match=f"^polarity must be 0 or 1, got {value}$"):
            stream.feed_all(bad)
    got.append(stream.feed_all(events[half:]))
    for a, b in zip(got, expected):
        assert a.keys() == b.keys() and all(a[k].tobytes() == b[k].tobytes() for k in a)
    assert stream.close().counts == clean.close().counts


@pytest.mark.parametrize("fuse", [True, False])
def test_times_beyond_the_documented_range_are_refused(fuse):
    """Issue 11: events after 2**62 µs were all dropped as 'refractory' (a sentinel collided)."""
    from tofnet.events import MAX_TIME_US
    stream = FixedBackend(fuse=fuse).open_stream(network(), intrinsics=INTRINSICS,
                                                 velocity_source=ConstantVelocity(VELOCITY))
    late = make_events([MAX_TIME_US - 5, MAX_TIME_US + 5], [1, 2], [1, 1], [1, 1])
    with pytest.raises(BackendError, match=r"\|t\| < 2\*\*61"):
        stream.feed(late)
    near = make_events([MAX_TIME_US - 5_000, MAX_TIME_US - 1_000], [1, 2], [1, 1], [1, 1])
    stream.feed(near)  # just inside: accepted, and the filter still sees both events
    assert stream.close().accepted == 2


def test_fused_and_model_by_model_streams_count_the_steps_a_promise_ran():
    """A promise (until_us) past the last event completes steps; both kinds of stream count them
    (the fused one counted only up to the last event and the latency)."""
    events = recording(60_000, seed=7).events
    steps = {}
    for fuse in (True, False):
        stream = FixedBackend(fuse=fuse).open_stream(network(), intrinsics=INTRINSICS,
                                                     velocity_source=ConstantVelocity(VELOCITY), t0_us=0)
        stream.feed_all(events)
        plain = stream.end_step() if not fuse else None
        stream.feed_all(events[:0], until_us=200_000)  # nothing more came by 200 ms
        steps[fuse] = stream.close().steps
    assert plain is not None and plain < 200 and steps[True] == steps[False] == 200
