"""Issue 27 item 5: a refused packet or value leaves a session (or stream) as it was and usable;
every misuse is one line of ``TofnetError``; monitors are checked when added."""

import numpy as np
import pytest

from tofnet import Monitor, Session
from tofnet.backends.event_driven import FixedBackend
from tofnet.backends.multiproc import MultiprocBackend
from tofnet.compiler import compile_network
from tofnet.errors import BackendError, TofnetError
from tofnet.io.recording import ConstantVelocity, Recording
from tofnet.networks import depth_network
from tofnet.testing import TEST_INTRINSICS, moving_pattern

SENSOR = (24, 16)
VELOCITY = (-0.5, 0.2, 0.1)
EVENTS = moving_pattern(SENSOR, (300, -150), 100_000, seed=1)
COMPILED = compile_network(depth_network(SENSOR, input={"refractory": "1ms"},
                                         velocity={"source": "constant", "velocity": list(VELOCITY)}), patch=(8, 8))


def one_line(err) -> str:
    message = str(err.value)
    assert isinstance(err.value, TofnetError) and "\n" not in message and message
    return message


def live(backend, fuse=False, **options):
    return Session(COMPILED, backend=backend, intrinsics=TEST_INTRINSICS, velocity_source=ConstantVelocity(VELOCITY),
                   t0_us=0, fuse=fuse, **options)


@pytest.fixture(scope="module")
def workers():
    with MultiprocBackend(workers=2).session() as session:
        yield session


def same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(a[k].tobytes() == b[k].tobytes() for k in a)


@pytest.mark.parametrize("name", ["fixed", "fixed fused", "reference", "multiproc", "multiproc fused"])
def test_a_refused_packet_leaves_a_live_session_open_and_unchanged(name, workers):
    """It used to end the session: the next valid packet got "session is failed; open a new one"."""
    backend = workers if name.startswith("multiproc") else name.split()[0]
    fuse = name.endswith("fused")
    half = len(EVENTS) // 2
    with live(backend) as clean:  # model by model
        expected = [clean.feed(EVENTS[:half]), clean.feed(EVENTS[half:], until_us=200_000)]
        expected_result = clean.finish()
    with live(backend, fuse) as session:
        assert session.fused == fuse
        got = [session.feed(EVENTS[:half])]
        for bad, until in ((EVENTS[:10], None), (list(EVENTS[half:half + 3]), None), (EVENTS[half:], 2**63),
                           (EVENTS[half:], int(EVENTS["t"][-1]) - 1), (EVENTS[half:], "soon")):
            with pytest.raises(BackendError) as err:
                session.feed(bad, until_us=until)
            one_line(err)
        got.append(session.feed(EVENTS[half:], until_us=200_000))
        result = session.finish()
    assert all(same(a, b) for a, b in zip(got, expected))
    assert result.counts == expected_result.counts and same(result.outputs, expected_result.outputs)


@pytest.mark.parametrize("name", ["fixed", "fixed fused", "reference", "multiproc", "multiproc fused"])
def test_a_live_session_refuses_a_polarity_other_than_0_or_1_and_goes_on(name, workers):
    """Any non-zero polarity ran as ON with no message; refused as the writers refuse it, the session unchanged."""
    backend = workers if name.startswith("multiproc") else name.split()[0]
    half = len(EVENTS) // 2
    with live(backend) as clean:
        expected = [clean.feed(EVENTS[:half]), clean.feed(EVENTS[half:], until_us=200_000)]
    bad = EVENTS[half:].copy()
    bad["p"][bad["p"] == 0] = 255
    with live(backend, name.endswith("fused")) as session:
        got = [session.feed(EVENTS[:half])]
        with pytest.raises(BackendError) as err:
            session.feed(bad)
        assert one_line(err) == "polarity must be 0 or 1, got 255"
        got.append(session.feed(EVENTS[half:], until_us=200_000))
    assert all(same(a, b) for a, b in zip(got, expected))


@pytest.mark.parametrize("value", [-2**63, np.inf, -np.inf, np.nan, 2.0**63, 2**61, "20", 1.5, [1, 2, 3]])
def test_set_refuses_values_a_variable_cannot_hold_naming_the_range(value):
    """-2**63 or inf in input.last_accepted wrapped int64 (6,013 events accepted instead of 23,746)."""
    with Session(COMPILED, Recording(EVENTS, intrinsics=TEST_INTRINSICS), backend="fixed") as session:
        session.run(steps=20)
        before = session.get("input.last_accepted").copy()
        with pytest.raises(BackendError) as err:
            session.set("input.last_accepted", value)
        message = one_line(err)
        assert message.startswith("input.last_accepted: ")
        if isinstance(value, int):
            assert "-4611686018427387904 .. 2305843009213693951 µs" in message
        assert np.array_equal(session.get("input.last_accepted"), before)
        session.set("input.last_accepted", -2**62)  # the documented "never" is accepted
        session.run(steps=5)


def test_set_refuses_counters_beyond_their_bits_and_keeps_the_values():
    with Session(COMPILED, Recording(EVENTS, intrinsics=TEST_INTRINSICS), backend="fixed") as session:
        session.run(steps=30)
        before = session.get("time_of_travel.counter").copy()
        for value in (2.0**64, -1, 0.5, "x"):
            with pytest.raises(BackendError) as err:
                session.set("time_of_travel.counter", value)
            one_line(err)
        assert np.array_equal(session.get("time_of_travel.counter"), before)


def test_run_until_out_of_range_is_refused_before_any_work():
    """until_us=2**63 tried to allocate 65.5 PiB; a session's run(until=...) checks the same way."""
    with Session(COMPILED, Recording(EVENTS, intrinsics=TEST_INTRINSICS), backend="fixed") as session:
        session.run(steps=3)
        for until in (float("nan"), float("inf"), 2.0**63, "1s", None):
            if until is None:
                with pytest.raises(TofnetError) as err:
                    session.run(steps=2**62)
            else:
                with pytest.raises(TofnetError) as err:
                    session.run(until=until)
            one_line(err)
        assert session.step == 3
        session.run(steps=2)
        assert session.step == 5


def test_a_promise_too_far_ahead_to_run_is_one_line():
    """In the time range but 2.3e15 steps ahead: numpy's MemoryError became a traceback. Now refused
    before anything changes (more than 2**32 steps at once), so the session goes on."""
    with live("fixed") as session, live("fixed") as clean:
        expected = [clean.feed(EVENTS[:100]), clean.feed(EVENTS[100:200], until_us=200_000)]
        got = [session.feed(EVENTS[:100])]
        with pytest.raises(BackendError) as err:
            session.feed(EVENTS[100:200], until_us=2**61 - 1)
        assert "more than 2**32" in one_line(err)
        got.append(session.feed(EVENTS[100:200], until_us=200_000))
        assert all(same(a, b) for a, b in zip(got, expected)) and len(got[1]["depth.depth"])


@pytest.mark.parametrize("name", ["fixed", "reference"])
def test_a_bare_graph_stream_refuses_a_promise_too_far_ahead(name):
    """``open_stream(...).feed(events, until_us=2**61 - 1)`` ended in numpy's MemoryError (16.4 PiB)."""
    from tofnet.backends.registry import get_backend
    options = {"fuse": False} if name == "fixed" else {}
    streams = [get_backend(name, **options).open_stream(COMPILED.network, intrinsics=TEST_INTRINSICS,
                                                        velocity_source=ConstantVelocity(VELOCITY), t0_us=0)
               for _ in range(2)]
    with pytest.raises(BackendError) as err:
        streams[0].feed_all(EVENTS[:100], until_us=2**61 - 1)
    assert one_line(err).startswith("stream: this packet would run 2305843009213693 steps at once")
    assert same(*(stream.feed_all(EVENTS[:100], until_us=200_000) for stream in streams))  # nothing changed


def test_out_of_memory_while_a_graph_stream_runs_is_one_line_and_closes_it(monkeypatch):
    from tofnet.backends.graph import GraphExecutor
    stream = FixedBackend(fuse=False).open_stream(COMPILED.network, intrinsics=TEST_INTRINSICS,
                                                  velocity_source=ConstantVelocity(VELOCITY), t0_us=0)

    def no_memory(self, end):
        raise MemoryError
    monkeypatch.setattr(GraphExecutor, "advance", no_memory)
    with pytest.raises(BackendError) as err:
        stream.feed_all(EVENTS[:100], until_us=200_000)
    assert "out of memory running steps 0 to 200 at once" in one_line(err)
    with pytest.raises(BackendError, match="stream is closed"):
        stream.feed_all(EVENTS[100:200])


def test_a_monitor_outside_the_sensor_is_refused_and_not_installed():
    """It raised IndexError and stayed installed, so every later run() failed."""
    with Session(COMPILED, Recording(EVENTS, intrinsics=TEST_INTRINSICS), backend="fixed",
                 monitors=["time_of_travel.counter@3,4"]) as session:
        session.run(steps=4)
        for bad in (["time_of_travel.counter@24,0"], ["input.last_accepted@0,16"], [Monitor("input.nope")],
                    ["time_of_travel.counter@1,1", "depth.a_t@100,1"], [3]):
            with pytest.raises(TofnetError) as err:
                session.add_monitors(bad)
            one_line(err)
        assert [m.target for m in session.monitors] == ["time_of_travel.counter"]
        session.run(steps=4)
        assert session.monitors[0].values.shape == (9, 4, 1)
    with pytest.raises(TofnetError) as err:
        Session(COMPILED, Recording(EVENTS, intrinsics=TEST_INTRINSICS), backend="fixed",
                monitors=["input.last_accepted@30,1"])
    assert "outside the 24x16 sensor" in one_line(err)


@pytest.mark.parametrize("pixels", [[("a", 1)], [(1, 2, 3)], [(-1, 0)], [(1.5, 2)], [5]])
def test_monitor_pixels_are_whole_pairs(pixels):
    with pytest.raises(TofnetError) as err:
        Monitor("input.last_accepted", pixels=pixels)
    one_line(err)


def test_a_fused_stream_refuses_until_us_before_the_packets_last_event():
    """The graph stream refused it, the fused one accepted it."""
    streams = [FixedBackend(fuse=fuse).open_stream(COMPILED.network, intrinsics=TEST_INTRINSICS,
                                                   velocity_source=ConstantVelocity(VELOCITY), t0_us=0)
               for fuse in (True, False)]
    half = len(EVENTS) // 2
    for stream in streams:
        for until in (int(EVENTS["t"][half - 1]), int(EVENTS["t"][half - 1]) - 5_000, 2**63, -2**63, 1.5):
            with pytest.raises(BackendError) as err:
                stream.feed_all(EVENTS[:half], until_us=until)
            one_line(err)
    assert type(streams[0]).__name__ == "FusedStream"
    outputs = [stream.feed_all(EVENTS[:half], until_us=int(EVENTS["t"][half - 1]) + 1) for stream in streams]
    assert same(*outputs) and len(outputs[0][COMPILED.network.processes[2].name + ".depth"])


def test_more_misuses_are_one_line_and_leave_the_session_usable():
    for target in (5, "input", "input.last_accepted@1,1", None):
        with pytest.raises(TofnetError) as err:
            Monitor(target)
        one_line(err)
    with Session(COMPILED, Recording(EVENTS, intrinsics=TEST_INTRINSICS), backend="fixed",
                 monitors="input.last_accepted@1,1") as session:  # one monitor, not its characters
        with pytest.raises(BackendError) as err:
            session.feed(EVENTS[:10])  # a recording's session runs it; feed is for a live source
        assert "use run" in one_line(err)
        session.run(steps=3)
        assert session.monitors[0].values.shape == (4, 1)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_fused_live_session_hands_back_what_a_model_by_model_one_does(workers):
    """``tofnet live`` runs the paper's chain through the fused kernel (fuse=True): the same records per
    packet, and what it cannot do (no process state) is one line."""
    ends = list(range(12_500, 100_001, 12_500))  # µs: packets of 12.5 ms, each promising its end
    cuts = np.concatenate([[0], np.searchsorted(EVENTS["t"], ends)])
    got = {}
    for fuse in (False, True):
        with live("fixed", fuse, backend_options={"workers": workers}) as session:
            got[fuse] = [session.feed(EVENTS[a:b], until_us=end) for a, b, end in zip(cuts[:-1], cuts[1:], ends)]
            assert session.output_latency("depth.depth") == 2
            if fuse:
                for action in (lambda: session.get("time_of_travel.counter"), lambda: session.step,
                               lambda: session.set("input.refractory", "2ms"), session.counts,
                               lambda: session.add_monitors(["depth.depth"])):
                    with pytest.raises(TofnetError) as err:
                        action()
                    assert "fuse=True" in one_line(err)
                assert session.monitors == []  # nothing added; the session goes on below
            with pytest.raises(TofnetError) as err:
                session.output_latency("depth.nope")
            assert "no output 'depth.nope'" in one_line(err) and "depth.depth" in str(err.value)
            got[fuse].append(session.finish())
    assert sum(len(p["depth.depth"]) for p in got[True][:-1]) > 0
    assert all(same(a, b) for a, b in zip(got[True][:-1], got[False][:-1]))
    assert got[True][-1].counts == got[False][-1].counts
    recording = Recording(EVENTS, intrinsics=TEST_INTRINSICS, sensor_size=SENSOR)
    for bad in (dict(network=COMPILED, recording=recording, fuse=True),
                dict(network=COMPILED, intrinsics=TEST_INTRINSICS, monitors=["depth.depth"], fuse=True)):
        with pytest.raises(TofnetError) as err:
            Session(**bad)
        assert "fuse=True" in one_line(err)
