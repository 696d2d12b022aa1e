"""The multiproc backend: bit-identity with ``fixed``, and failures that end cleanly and loudly.

Spawning workers costs about a second, so one session serves every equality test and
each failure test starts (and must cleanly lose) its own small one.
"""

import gc
import os
import signal

import numpy as np
import pytest

from tofnet.backends.event_driven import FixedBackend
from tofnet.backends.multiproc import MultiprocBackend
from tofnet.backends.remote import plan_workers, routing_table
from tofnet.compiler import compile_network
from tofnet.errors import BackendError
from tofnet.io.recording import Recording
from tofnet.networks import depth_network
from tofnet.testing import TEST_INTRINSICS, merge_events, moving_pattern, noise_events

SENSOR = (24, 16)


def network(distance=1, per="pixel", update_every=1, refractory=0):
    return depth_network(SENSOR, input={"refractory": refractory},
                         time_of_travel={"distance": distance},
                         velocity={"source": "constant", "velocity": [-0.5, 0.2, 0.1], "per": per,
                                   "patch_size": 5, "update_every": update_every})


def texture(seed=0):
    events = moving_pattern(SENSOR, (300, -150), 200_000, seed=seed)
    return Recording(merge_events(events, noise_events(SENSOR, 5, 200_000, seed=seed)), intrinsics=TEST_INTRINSICS)


def ordered(result):
    depth = result.depth[np.lexsort((result.depth["x"], result.depth["y"], result.depth["step"]))]
    tot = result.tot[np.lexsort((result.tot["direction"], result.tot["x"], result.tot["y"], result.tot["step"]))]
    return depth, tot


def assert_identical(result, expected):
    depth, tot = ordered(expected)
    assert result.depth.tobytes() == depth.tobytes()  # bit for bit, in (step, y, x) order
    assert result.tot.tobytes() == tot.tobytes()
    for field in ("events_in", "accepted", "dropped", "rejected", "tot_spikes", "steps", "t0_us"):
        assert getattr(result, field) == getattr(expected, field), field


@pytest.fixture(scope="module")
def session():
    with MultiprocBackend(workers=2, chunk_steps=40).session() as s:
        yield s


@pytest.mark.parametrize("options,patch", [
    ({}, (8, 8)),
    ({"distance": 2}, (8, 8)),
    ({"per": "patch", "update_every": 3, "refractory": "2ms"}, (7, 5)),
    ({}, {"time_of_travel": (8, 8), "depth": (12, 16)}),  # depth cores span two time-of-travel cores
])
def test_equals_the_fixed_backend_bit_for_bit(session, options, patch):
    compiled = compile_network(network(**options), patch=patch)
    recording = texture()
    result = session.run(recording, compiled=compiled, record_tot=True)
    assert len(result.depth) > 100
    assert_identical(result, FixedBackend().run(compiled, recording, record_tot=True))


def test_a_process_that_acts_without_input_counts_only_the_steps_the_run_ran(session):
    """The session runs in chunks of 40 steps; the last one must end where the run does, not at its
    chunk's end (a core-placed heartbeat counted 2400 beats against fixed's 1488)."""
    from tofnet.core.network import Network
    from tofnet.testing import HeartbeatProcess

    beating = Network(list(network().processes) + [HeartbeatProcess(name="beat", sensor_size=SENSOR)])
    compiled = compile_network(beating, patch=(8, 8))
    recording = texture()
    recording.events = recording.events[recording.events["t"] < 165_000]  # its last chunk: steps 160-199
    expected = FixedBackend().run(compiled, recording)
    assert expected.steps < 200  # the run ends inside its last chunk
    result = session.run(recording, compiled=compiled)
    assert expected.counts["beat"]["beats"] >= expected.steps * min(SENSOR)  # a beat per step, steps it ran
    assert result.counts["beat"] == expected.counts["beat"] and result.steps == expected.steps
    assert result.outputs["beat.beat"].tobytes() == expected.outputs["beat.beat"].tobytes()


def test_a_full_240x180_scene_equals_the_fixed_backend_bit_for_bit(session):
    from tofnet.sim.engine import generate
    from tofnet.sim.scenarios import scenario

    recording = generate(scenario("slider", 0.3), seed=0).to_recording()  # ~520k events, textured
    compiled = compile_network(depth_network((240, 180)), patch=(30, 30))  # the paper's 48 + 48 cores
    result = session.run(recording, compiled=compiled, record_tot=True)
    assert len(recording.events) > 300_000 and len(result.depth) > 20_000
    assert result.extra["workers"] == 2
    assert_identical(result, FixedBackend().run(compiled, recording, record_tot=True))


def test_the_summary_says_how_a_model_by_model_run_was_split(session):
    from tofnet.networks import improved_network

    paper = compile_network(network(), patch=(8, 8))  # 6 cores per layer, 3 for each worker
    stream = session.open_stream(paper, recording=texture(), fuse=False)
    stream.feed_all(texture().events)
    split = stream.close().summary()["workers"]
    assert split["threads"] == 2 and split["bands"] == 2 and "velocity" in split["whole"]
    assert "time_of_travel" not in split["whole"]
    # the time surface is placed on the host: nothing for the workers, and the summary says so
    estimator = compile_network(improved_network(SENSOR, velocity={"source": "constant",
                                                                    "velocity": [-0.5, 0.2, 0.1]}))
    result = session.run(texture(), compiled=estimator)
    assert result.summary()["workers"] == {"threads": 1, "bands": 1, "whole": [p.name for p in
                                                                               estimator.network.processes
                                                                               if p.placement != "core"],
                                           "unit": "processes"}
    assert "time_surface" in result.summary()["workers"]["whole"]


def test_a_session_keeps_its_workers_between_runs(session):
    pids = session.pids
    compiled = compile_network(network(), patch=(8, 8))
    first = session.run(texture(1), compiled=compiled)
    second = session.run(texture(1), compiled=compiled)
    assert session.pids == pids and len(pids) == 2
    assert first.depth.tobytes() == second.depth.tobytes()


def test_a_bad_recording_is_reported_without_losing_the_workers(session):
    from tofnet.errors import DataError
    pids = session.pids
    compiled = compile_network(network(), patch=(8, 8))
    uncalibrated = Recording(texture().events)  # no intrinsics: the velocity process cannot work
    with pytest.raises(DataError, match="calib"):
        session.run(uncalibrated, compiled=compiled)
    assert session.pids == pids and len(session.run(texture(), compiled=compiled).depth) > 0


def test_workers_are_spawned_not_forked(session):
    for pid in session.pids:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            assert b"multiprocessing.spawn" in f.read()


def test_a_row_load_cuts_the_workers_shares_between_rows_of_patches_nearest_equal_load():
    compiled = compile_network(depth_network((240, 180)), patch=(30, 30))  # 8 x 6 patches per layer
    load = np.zeros(180)
    load[120:] = 1.0  # all events in the lowest two rows of patches
    tot = [c.index for c in compiled.cores_of("time_of_travel")]
    plans = plan_workers(compiled, 2, load)
    assert [c for c in plans[0].cores if c in tot] == tot[:40]  # cut at row 150: half of the load each
    three = plan_workers(compiled, 3, load)  # a row of patches at least each; the busy two apart
    assert [sum(c in tot for c in p.cores) for p in three] == [8, 32, 8]
    assert plan_workers(compiled, 2, np.zeros(180)) == plan_workers(compiled, 2)  # no load: equal groups


def test_the_paper_mapping_puts_48_cores_on_each_of_two_workers():
    compiled = compile_network(depth_network((240, 180)), patch=(30, 30))  # the paper's 48 + 48 cores
    plans = plan_workers(compiled, 2)
    assert [len(p.cores) for p in plans] == [48, 48]
    for plan in plans:  # each worker holds half of each layer
        assert sum(compiled.cores[c].process == "time_of_travel" for c in plan.cores) == 24
    route = routing_table(compiled, plans, "time_of_travel")
    tot_cores = compiled.cores_of("time_of_travel")
    ys, xs = np.mgrid[0:180, 0:240]
    for plan in plans:  # a worker receives exactly the union of its cores' halos
        expected = np.zeros((180, 240), dtype=bool)
        for core in tot_cores:
            if core.index in plan.cores:
                expected |= core.receives_mask(xs, ys)
        assert np.array_equal(route[plan.index], expected)
    assert route.sum(axis=0).max() == 2 and route.any(axis=0).all()  # halos overlap at the seam only


def test_run_opens_and_closes_its_own_session(session):
    before = set(_children())
    compiled = compile_network(network(), patch=(12, 8))
    recording = texture(2)
    result = MultiprocBackend(workers=2).run(compiled, recording, record_tot=True)
    assert_identical(result, FixedBackend().run(compiled, recording, record_tot=True))
    assert result.extra["workers"] == 2 and set(_children()) == before
    # starting the workers (spawn, imports, warm-up: seconds) is the run's set-up, not the network's time
    assert result.setup_time >= result.extra["startup_s"] > result.wall_time


# -- failures: each must raise clearly, never hang, and leave nothing behind ---------------

def _children() -> list[int]:
    """Live child processes of this one, except multiprocessing's resource tracker."""
    me, out = os.getpid(), []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmdline = f.read()
        except OSError:
            continue
        if ppid == me and b"resource_tracker" not in cmdline:
            out.append(int(entry))
    return out


@pytest.fixture
def leak_check(session):
    """Compare fds, /dev/shm and child processes before and after (``session``: the shared
    workers and multiprocessing's resource tracker already exist, so the counts are stable)."""
    before = (set(os.listdir("/proc/self/fd")), set(os.listdir("/dev/shm")), set(_children()))
    pids: list[int] = []
    yield pids
    # a run's estimates live in memory the workers map (``SharedBandKernel.allocate``) until the last array
    # on it goes; a test's ``pytest.raises`` result holds its frame (a reference cycle) and so the run's
    gc.collect()
    after = (set(os.listdir("/proc/self/fd")), set(os.listdir("/dev/shm")), set(_children()))
    assert after[0] == before[0], "leaked file descriptors"
    # tofnet's shared buffers are memfds, never in /dev/shm; other programs on a shared machine
    # create and remove Python's psm_/sem.mp- entries there meanwhile, which are not ours
    ours = {name for name in after[1] ^ before[1] if not name.startswith(("psm_", "sem.mp-"))}
    assert not ours, "leaked shared memory"
    with open("/proc/self/maps") as maps:
        assert "memfd:tofnet" not in maps.read(), "a shared buffer is still mapped"
    assert after[2] == before[2], "orphaned processes"
    assert pids and not any(os.path.exists(f"/proc/{pid}") for pid in pids)


def _failing_session(pids, **options):
    options.setdefault("start_timeout", 120.0)  # a loaded machine may take seconds to start workers
    backend = MultiprocBackend(workers=2, chunk_steps=20, **options)
    s = backend.session(compile_network(network(), patch=(8, 8)))
    s.open()
    pids.extend(s.pids)
    return s


def test_an_exception_in_a_worker_reaches_the_caller_with_its_traceback(leak_check):
    s = _failing_session(leak_check)
    s._inject_fault(1, "raise")
    with pytest.raises(BackendError) as err:
        s.run(texture())
    message = str(err.value)
    assert "worker 1 failed" in message and "Traceback" in message
    assert "InjectedFault: fault injected into worker 1" in message
    with pytest.raises(BackendError, match="failed earlier"):
        s.run(texture())


def test_a_worker_killed_between_runs_is_reported(leak_check):
    s = _failing_session(leak_check)
    os.kill(s.pids[0], signal.SIGKILL)
    with pytest.raises(BackendError, match=r"worker 0 \(pid \d+\) .*SIGKILL"):
        s.run(texture())


def test_a_worker_killed_mid_run_is_reported(leak_check):
    s = _failing_session(leak_check)
    s._inject_fault(0, "kill")
    with pytest.raises(BackendError, match=r"worker 0 \(pid \d+\) died while running chunk \d+: killed by signal 9"):
        s.run(texture())


def test_a_hung_worker_times_out(leak_check):
    s = _failing_session(leak_check, timeout=2.0)
    s._inject_fault(1, "hang")
    with pytest.raises(BackendError, match=r"worker 1 .* did not answer within 2 s .*timeout"):
        s.run(texture())


def test_workers_that_do_not_start_in_time_are_reported(leak_check, monkeypatch):
    from tofnet.backends import _channel
    start = _channel.Channel.__init__

    def start_and_note_pid(self, ctx, index):
        start(self, ctx, index)
        leak_check.append(self.process.pid)
    monkeypatch.setattr(_channel.Channel, "__init__", start_and_note_pid)
    s = MultiprocBackend(workers=2, start_timeout=0.01).session()
    with pytest.raises(BackendError, match=r"worker 0 .* did not answer within 0.01 s while starting.*start_timeout"):
        with s:
            pass
    assert len(leak_check) == 2 and s.pids == []


def test_ctrl_c_in_the_parent_stops_every_worker(leak_check):
    def interrupt(done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        with _failing_session(leak_check) as s:
            s.run(texture(), progress=interrupt)


def test_bad_options_are_rejected():
    with pytest.raises(BackendError, match="workers"):
        MultiprocBackend(workers=-1)
    from tofnet.machine import cpu_count
    assert MultiprocBackend(workers=0).workers == MultiprocBackend(workers="auto").workers == cpu_count()
    with pytest.raises(BackendError, match="timeout"):
        MultiprocBackend(timeout=0)
    for option in ("timeout", "start_timeout"):  # 1e300 s reached the waits: OverflowError
        for value in (1e300, 86_401, 10**400):
            with pytest.raises(BackendError, match=rf"multiproc: {option} must be a positive number of seconds, "
                                                   rf"at most 86400 \(a day\), got"):
                MultiprocBackend(workers=1, **{option: value})
    assert MultiprocBackend(workers=1, timeout=86_400).timeout == 86_400.0


def test_one_timeout_bounds_the_start_too(leak_check, monkeypatch):
    """A worker stopped (SIGSTOP) while starting is reported after ``timeout``: start-up has no longer wait."""
    from tofnet.backends import _channel
    start = _channel.Channel.__init__

    def start_and_stop_one(self, ctx, index):
        start(self, ctx, index)
        leak_check.append(self.process.pid)
        if index == 1:
            os.kill(self.process.pid, signal.SIGSTOP)
    monkeypatch.setattr(_channel.Channel, "__init__", start_and_stop_one)
    backend = MultiprocBackend(workers=2, timeout=3.0)
    assert backend.start_timeout == 3.0
    s = backend.session()
    with pytest.raises(BackendError, match=r"worker 1 .* did not answer within 3 s while starting"):
        with s:
            pass


def test_the_worker_check_runs_multiproc_in_both_its_modes():
    """``tofnet conformance --backend multiproc --workers 1,2`` once failed on every case: it asked
    multiproc for ``fuse``, which only the in-process backends take (``Backend.run_modes``)."""
    from tofnet.conformance.workers import check_workers

    results = check_workers("multiproc", (1, 2), ["edge+u-v"])
    assert [r.mode for r in results] == ["bands-1", "bands-2", "bands-1-per-core", "bands-2-per-core"]
    assert all(r.ok for r in results), [r.first for r in results]
    assert all(r.estimates[0] > 0 for r in results)


def test_a_script_on_stdin_is_told_its_processes_need_a_module():
    """Its workers cannot import what a script without a file defines; the hint said to guard the
    main module, which it was."""
    import subprocess
    import sys
    script = """
from tofnet import InputProcess, Network, Payload, PortSpec, Process
from tofnet.backends import get_backend
from tofnet.io.recording import Recording
from tofnet.models import StepModel, model
from tofnet.testing import TEST_INTRINSICS, moving_pattern
class StdinGateProcess(Process):
    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes"),)
    outports = (PortSpec("passed", Payload.POLARITY, 1, "spikes"),)
    resources_per_pixel = {"accumulators": 1}
@model(StdinGateProcess)
class StdinGateModel(StepModel):
    def step(self, k, inbox):
        return {"passed": inbox.get("events")}
source, gate = InputProcess(name="input", sensor_size=(24, 16)), StdinGateProcess(name="gate")
source.events.connect(gate.events)
recording = Recording(moving_pattern((24, 16), (300, -150), 20_000, seed=1), intrinsics=TEST_INTRINSICS)
try:
    get_backend("multiproc", workers=2, timeout=60).run(Network([source, gate]), recording)
except Exception as err:
    print(type(err).__name__, err)
"""
    done = subprocess.run([sys.executable], input=script, capture_output=True, text=True, timeout=120)
    assert done.stdout.startswith("BackendError multiproc worker"), done.stdout + done.stderr[-2000:]
    assert "the main script has no file (stdin, -c or an interactive session)" in done.stdout.lower()
    assert "put your processes and models in a module" in done.stdout

