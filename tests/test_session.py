"""Run control: chunks of any size equal one run, variables, parameters, monitors, cleanup — on every backend."""

import contextlib
import os

import numpy as np
import pytest

from tofnet import Monitor, Session
from tofnet.backends.multiproc import MultiprocBackend
from tofnet.backends.registry import available_backends, get_backend
from tofnet.compiler import compile_network
from tofnet.errors import BackendError, NetworkError, TofnetError
from tofnet.io.recording import Recording
from tofnet.kernels.input_filter import InputFilter
from tofnet.networks import denoised_network, depth_network
from tofnet.testing import TEST_INTRINSICS, merge_events, moving_pattern, noise_events

SENSOR = (24, 16)
VELOCITY = {"source": "constant", "velocity": [-0.5, 0.2, 0.1], "per": "pixel"}
RECORDING = Recording(merge_events(moving_pattern(SENSOR, (300, -150), 100_000, seed=1),
                                   noise_events(SENSOR, 20, 100_000, seed=2)), intrinsics=TEST_INTRINSICS)
COMPILED = compile_network(denoised_network(SENSOR, input={"refractory": "1ms"}, denoise={"window": "4ms"},
                                            velocity=VELOCITY), patch=(8, 8))
VARIABLES = ["input.last_accepted", "denoise.last_spike", "time_of_travel.counter", "time_of_travel.polarity",
             "depth.a_t", "velocity.last_velocity"]


@pytest.fixture(scope="module")
def workers():
    with MultiprocBackend(workers=2).session() as session:
        yield session


def backend_of(name, workers):
    return workers if name == "multiproc" else name


@pytest.mark.parametrize("name", available_backends())
def test_chunks_of_1_7_and_1000_steps_equal_one_run(name, workers):
    whole = get_backend(name, **({"workers": 2} if name == "multiproc" else {})).run(COMPILED, RECORDING,
                                                                                      record_tot=True)
    assert len(whole.depth) > 500
    for chunk in (1, 7, 1000):
        with Session(COMPILED, RECORDING, backend=backend_of(name, workers), probes=["time_of_travel.counts"]) as s:
            while s.step < 105:
                s.run(steps=chunk)
            ran = s.step  # past the run's end (103): those steps ran too
            result = s.finish()
        for key, records in whole.outputs.items():
            assert result.outputs[key].tobytes() == records.tobytes(), (chunk, key)
        assert result.counts == whole.counts and result.steps == max(whole.steps, ran) and whole.steps == 103


def test_variables_agree_across_backends_at_every_step(workers):
    sessions = {name: Session(COMPILED, RECORDING, backend=backend_of(name, workers))
                for name in ("reference", "float", "fixed", "multiproc")}
    with contextlib.ExitStack() as stack:
        for s in sessions.values():
            stack.enter_context(s)
        for step in (0, 13, 40, 77):
            values = {}
            for name, s in sessions.items():
                s.run(steps=step - s.step)
                assert s.step == step and s.time == pytest.approx(step * 1e-3)
                values[name] = {v: s.get(v) for v in VARIABLES}
            for v in VARIABLES:
                for name in sessions:
                    assert np.array_equal(values[name][v], values["reference"][v], equal_nan=True), (step, v, name)
        counter = values["reference"]["time_of_travel.counter"]
        assert counter.shape == (4, 16, 24) and counter.max() > 1 and (counter > 0).sum() > 100


@pytest.mark.parametrize("name", ["reference", "fixed", "multiproc"])
def test_variables_round_trip_and_read_only_ones_refuse(name, workers):
    with Session(COMPILED, RECORDING, backend=backend_of(name, workers)) as s:
        s.run(steps=30)
        counter = s.get("time_of_travel.counter").copy()
        counter[0, 3, 4], counter[1] = 7, 0
        s.set("time_of_travel.counter", counter)
        assert np.array_equal(s.get("time_of_travel.counter"), counter)
        s.set("denoise.last_spike", 12)  # broadcast to every pixel
        assert (s.get("denoise.last_spike") == 12).all()
        s.set("input.last_accepted", np.full((16, 24), 29_000))
        assert (s.get("input.last_accepted") == 29_000).all()
        with pytest.raises(BackendError, match="read-only"):
            s.set("depth.a_t", 0.0)
        with pytest.raises(BackendError, match="shape"):
            s.set("time_of_travel.counter", np.zeros((3, 3)))
        with pytest.raises(BackendError, match="counter values"):
            s.set("time_of_travel.counter", 999)
        with pytest.raises(NetworkError, match="no variable 'nope'"):
            s.executor.get_var("depth", "nope")


@pytest.mark.parametrize("name", ["fixed", "multiproc"])
def test_a_refused_value_changes_nothing_and_the_session_goes_on(name, workers):
    """multiproc answered the next message with a worker's stale refusal (every later session on those
    workers failed 'build'); now it says what a local model says, and nothing changed."""
    with Session(COMPILED, RECORDING, backend=backend_of(name, workers)) as s:
        s.run(steps=30)
        before = s.get("time_of_travel.counter").copy()
        with pytest.raises(BackendError) as refused:
            s.set("time_of_travel.counter", 999)
        assert str(refused.value) == "time_of_travel.counter: counter values must be in 0..255 (8-bit counters)"
        assert np.array_equal(s.get("time_of_travel.counter"), before)
        s.run(steps=10)
        assert s.step == 40
    again = Session(COMPILED, RECORDING, backend=backend_of(name, workers)).finish()
    assert len(again.depth) > 500


def test_a_parameter_changed_mid_recording_applies_from_then_on():
    net = depth_network(SENSOR, input={"refractory": "20ms"}, velocity=VELOCITY)
    with Session(net, RECORDING) as s:
        s.run(steps=50)
        s.set("input.refractory", "2ms")
        assert s.get("input.refractory") == 0.002 and net.process("input").refractory == 0.02  # the caller's is untouched
        result = s.finish()
    # the meaning: events before step 50 filtered with 20 ms, later ones with 2 ms
    events, t0 = RECORDING.events, int(RECORDING.events["t"][0])
    flt = InputFilter(SENSOR, t0, 1000, 20_000)
    cut = int(np.searchsorted(events["t"], t0 + 50_000))
    flt.feed(events[:cut])
    flt.refractory_us = 2_000
    flt.feed(events[cut:])
    assert result.accepted == flt.accepted and list(result.dropped.values()) == flt.drops.tolist()
    with pytest.raises(TofnetError, match="closed|finished"):
        s.run(steps=1)


def test_a_constant_velocity_changed_mid_recording():
    net = depth_network(SENSOR, input={"refractory": "1ms"}, velocity=VELOCITY)
    with Session(net, RECORDING) as s:
        s.run(steps=40)
        s.set("velocity.velocity", [-1.0, 0.4, 0.2])  # twice as fast: depths double from update 40 on
        s.run(steps=3)
        assert np.allclose(s.get("velocity.last_velocity"), [-1.0, 0.4, 0.2])
        with pytest.raises(BackendError, match="cannot change"):
            s.set("time_of_travel.distance", 2)
        assert s.get("time_of_travel.distance") == 1


def test_monitors_record_what_was_asked_and_no_more():
    monitors = [Monitor("time_of_travel.counter", every=5, pixels=[(3, 4), (10, 8)]),
                Monitor.parse("input.events@3,4;10,8"), Monitor("depth.a_t", every=50)]
    with Session(COMPILED, RECORDING, monitors=monitors) as s:
        s.run(steps=23)
        s.run(steps=40)
        result = s.finish()
    counter, events, a_t = monitors
    assert counter.steps == list(range(0, result.steps, 5)) and counter.values.shape == (len(counter.steps), 4, 2)
    assert counter.values.max() > 0
    assert a_t.values.shape == (len(a_t.steps), 2, 16, 24)
    spikes = events.values
    assert len(spikes) > 2 and set(zip(spikes["x"].tolist(), spikes["y"].tolist())) <= {(3, 4), (10, 8)}
    arrays = counter.arrays()
    assert set(arrays) == {"step", "values", "x", "y"} and arrays["x"].tolist() == [3, 10]
    with pytest.raises(TofnetError, match="PROCESS.VAR"):
        Monitor.parse("nonsense")


@pytest.mark.parametrize("name", ["reference", "fixed", "multiproc"])
def test_a_monitor_samples_every_step_the_run_ran_the_last_ones_in_flight_too(name, workers):
    """finish() runs the steps in flight after the last event (the network's latency): they ran, so the
    monitors sample them; and steps a session ran past the end count in the result's steps."""
    every_step = Monitor("time_of_travel.counter", every=1, pixels=[(3, 4)])
    with Session(COMPILED, RECORDING, backend=backend_of(name, workers), monitors=[every_step]) as s:
        result = s.finish()
    assert result.steps > 100 and every_step.steps == list(range(result.steps))
    with Session(COMPILED, RECORDING, backend=backend_of(name, workers)) as s:
        s.run(steps=result.steps + 20)
        past = s.finish()
    assert past.steps == result.steps + 20 and past.depth.tobytes() == result.depth.tobytes()


def test_stop_releases_the_workers_at_once():
    s = Session(COMPILED, RECORDING, backend="multiproc", backend_options={"workers": 2})
    pids = s._resource.pids
    s.run(steps=20)
    s.stop()
    assert pids and not any(os.path.exists(f"/proc/{pid}") for pid in pids)
    with pytest.raises(BackendError, match="stopped"):
        s.run(steps=1)


def test_the_variables_check_catches_a_backend_reporting_wrong_counters(monkeypatch):
    from tofnet.conformance import run_suite
    from tofnet.models.time_of_travel import TimeOfTravelEventModel

    original = TimeOfTravelEventModel.get_var

    def off_by_one(self, name, step):
        value = original(self, name, step)
        return value + (value > 0) if name == "counter" else value
    monkeypatch.setattr(TimeOfTravelEventModel, "get_var", off_by_one)
    (result,) = run_suite("fixed", "reference", cases=["variables-texture-blobs"])
    assert not result.ok and "variable time_of_travel.counter at step 9 differs" in result.first


def test_run_monitor_and_plot_units_from_the_command_line(tmp_path):
    from tofnet.cli import main
    from tofnet.io import write_ecd

    folder = tmp_path / "rec"
    write_ecd(folder, RECORDING.events, intrinsics=TEST_INTRINSICS, sensor_size=SENSOR)
    out = tmp_path / "d.npz"
    assert main(["run", str(folder), "--out", str(out), "--velocity=-0.5,0.2,0.1", "--refractory", "1ms",
                 "--sensor-size", "24x16", "--monitor", "time_of_travel.counter@3,4;10,8", "--monitor-every", "10",
                 "--quiet"]) == 0
    saved = np.load(tmp_path / "d.monitor.time_of_travel.counter.npz")
    assert saved["values"].shape == (len(saved["step"]), 4, 2) and saved["step"][1] == 10
    png = tmp_path / "units.png"
    assert main(["plot", "units", str(folder), "--pixel", "10,8", "--window", "0.02:0.06", "--out", str(png),
                 "--velocity=-0.5,0.2,0.1"]) == 0
    assert png.stat().st_size > 10_000
    np.save(tmp_path / "bare.npy", RECORDING.events)  # no calibration: the camera is given, as to tofnet run
    fx, fy, cx, cy = TEST_INTRINSICS.fx, TEST_INTRINSICS.fy, TEST_INTRINSICS.cx, TEST_INTRINSICS.cy
    assert main(["plot", "units", str(tmp_path / "bare.npy"), "--pixel", "10,8", "--window", "0.02:0.06",
                 "--out", str(tmp_path / "bare.png"), "--velocity=-0.5,0.2,0.1",
                 f"--intrinsics={fx},{fy},{cx},{cy}"]) == 0



def test_plot_units_never_overwrites_without_force_and_refuses_what_it_does_not_read(tmp_path, capsys):
    from tofnet.cli import main
    from tofnet.io import write_ecd

    folder = tmp_path / "rec"
    write_ecd(folder, RECORDING.events, intrinsics=TEST_INTRINSICS, sensor_size=SENSOR)
    units = ["plot", "units", str(folder), "--pixel", "10,8", "--window", "0.02:0.06", "--velocity=-0.5,0.2,0.1"]
    mine = tmp_path / "mine.png"
    mine.write_text("not tofnet's")
    assert main([*units, "--out", str(mine)]) == 2
    assert "exists" in capsys.readouterr().err and mine.read_text() == "not tofnet's"
    assert main([*units, "--out", str(tmp_path / "notes.txt")]) == 2
    assert "PNG" in capsys.readouterr().err and not (tmp_path / "notes.txt").exists()
    assert main([*units, "--out", str(mine), "--force"]) == 0 and mine.stat().st_size > 10_000
    for extra, flag in ((["--timestep", "2ms"], "--timestep"), (["--reduce", "median"], "--reduce"),
                        (["--no-gt"], "--no-gt"), (["--error-window", "5ms"], "--error-window")):
        assert main([*units, "--out", str(tmp_path / "u.png"), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0] and "not used" in err[0], err
    depth = tmp_path / "d.npz"
    assert main(["run", str(folder), "--out", str(depth), "--velocity=-0.5,0.2,0.1", "--quiet"]) == 0
    capsys.readouterr()
    for extra, flag in ((["--spec", "nosuch.yaml"], "--spec"), (["--backend", "nosuch"], "--backend"),
                        (["--velocity", "9,9,9"], "--velocity"), (["--pixel", "1,1"], "--pixel")):
        assert main(["plot", "depthmap", str(folder), str(depth), "--out", str(tmp_path / "m.png"), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0] and "not used" in err[0], err
    assert not (tmp_path / "u.png").exists() and not (tmp_path / "m.png").exists()


def test_a_session_asks_a_backend_what_it_declares_it_can_do():
    from tofnet.backends.base import Backend

    class RunOnly(Backend):  # a user's backend that only runs whole recordings
        name = "run-only"

        def run(self, compiled, recording, **options):
            raise AssertionError("not called")

    with pytest.raises(BackendError, match="offers no streams") as err:
        Session(COMPILED, RECORDING, backend=RunOnly())
    assert "\n" not in str(err.value)

    class Streaming(type(get_backend("fixed"))):  # declares "stream" by inheritance: sessions open it
        name = "streaming"

    with Session(COMPILED, RECORDING, backend=Streaming()) as s:
        s.run(steps=30)
        assert s.step == 30
    assert get_backend("multiproc").capabilities == {"stream", "workers", "bands"}


@pytest.mark.parametrize("name", ["fixed", "multiproc"])
def test_a_session_reports_its_set_up_apart_from_the_network_time(name, monkeypatch):
    """Building the models' state is set-up, as in ``run`` (it was counted as running the network)."""
    import time

    from tofnet.backends.graph import GraphExecutor
    build = GraphExecutor.__init__

    def slow_build(self, *args, **kwargs):
        time.sleep(0.2)
        build(self, *args, **kwargs)

    if name == "fixed":
        monkeypatch.setattr(GraphExecutor, "__init__", slow_build)
    started = time.perf_counter()
    session = Session(COMPILED, RECORDING, backend=MultiprocBackend(workers=2) if name == "multiproc" else name)
    result = session.finish()
    elapsed = time.perf_counter() - started
    if name == "fixed":
        assert result.setup_time >= 0.2 > result.wall_time
    else:  # starting the workers and building their models, before the stream's clock started
        assert result.setup_time > 0, result.setup_time
    assert result.wall_time + result.setup_time + result.compile_time <= elapsed + 1e-3, \
        (result.wall_time, result.setup_time, result.compile_time, elapsed)


@pytest.mark.parametrize("name,options", [("fixed", {"workers": 2}), ("multiproc", None), ("reference", None)])
def test_a_process_number_and_a_changed_parameter_mean_the_same_on_bands_and_workers(name, options, workers):
    """A ``vector`` variable is the whole process's: a process declaring one runs whole, so ``get``
    reads that number (bands answered one per region, and the gather failed). A parameter set in a
    session reaches ``self.process`` of the model on worker processes too, as on one machine."""
    from tofnet import InputProcess, Network
    from tofnet.testing import SpikeTallyProcess

    def network():
        source, tally = InputProcess(name="input", sensor_size=SENSOR), SpikeTallyProcess(name="tally", limit=100)
        source.events.connect(tally.events)
        return compile_network(Network([source, tally]), patch=(8, 8))

    def session_run(backend, backend_options):
        with Session(network(), RECORDING, backend=backend, backend_options=backend_options) as s:
            s.run(steps=30)
            seen = int(s.get("tally.tally")[0])
            s.set("tally.limit", 0)  # from now on every spike
            s.run(steps=30)
            s.set("tally.tally", 7)
            result = s.finish()
        return seen, result

    expected_seen, expected = session_run("fixed", None)
    seen, result = session_run(backend_of(name, workers), options)
    assert expected_seen == 100 and seen == expected_seen
    assert result.outputs["tally.passed"].tobytes() == expected.outputs["tally.passed"].tobytes()
    assert result.counts["tally"] == expected.counts["tally"] == {"passed": len(expected.outputs["tally.passed"])}
    assert len(expected.outputs["tally.passed"]) > 300  # 100 passed, then every spike
    if name != "reference":
        assert "tally" in result.summary()["workers"]["whole"]


@pytest.mark.parametrize("monitors", [[], ["time_of_travel.counter@3,4"]], ids=["no-monitor", "monitor"])
def test_a_session_that_keeps_no_outputs_hands_back_each_record_once(monitors):
    """keep_outputs=False: what run/feed return and then finish()'s outputs make the whole run
    (finish() dropped what its own run and, with a monitor, the steps in flight produced)."""
    whole = get_backend("fixed").run(COMPILED, RECORDING)
    with Session(COMPILED, RECORDING, backend="fixed", keep_outputs=False, monitors=monitors) as s:
        parts = [s.run(steps=30)]
        parts.append(s.finish().outputs)
    events = RECORDING.events
    with Session(COMPILED, intrinsics=TEST_INTRINSICS, backend="fixed", keep_outputs=False, monitors=monitors) as s:
        fed = [s.feed(events[lo:lo + 1000]) for lo in range(0, len(events), 1000)]
        fed.append(s.finish().outputs)
    for got in (parts, fed):
        depth = np.concatenate([part["depth.depth"] for part in got if len(part.get("depth.depth", ()))])
        assert depth.tobytes() == whole.depth.tobytes()


def test_a_parameter_change_is_all_or_none_across_a_processs_instances():
    """A worker holding several instances of a process: when one model refuses, none keeps the new value
    (the process copies and the models told before it go back)."""
    from tofnet.errors import BackendError as Refused
    from tofnet.models.base import apply_param
    from tofnet.testing import SpikeTallyProcess

    class Model:
        def __init__(self, refuses):
            self.refuses, self.seen = refuses, []

        def set_param(self, name, value):
            if self.refuses and value == 5:
                raise Refused("cannot change")
            self.seen.append(value)

    instances = [(SpikeTallyProcess(name="tally", limit=1), Model(False)),
                 (SpikeTallyProcess(name="tally", limit=1), Model(True))]
    with pytest.raises(Refused):
        apply_param(instances, "limit", 5)
    assert [process.limit for process, _ in instances] == [1, 1] and instances[0][1].seen == [5, 1]
    apply_param(instances[:1], "limit", 3)
    assert instances[0][0].limit == 3 and instances[0][1].seen == [5, 1, 3]
