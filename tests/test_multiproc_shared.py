"""multiproc over shared memory: each worker's cores as one band, the same bytes as fixed, nothing left behind."""

import gc
import os
import re
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from tofnet.backends.multiproc import MultiprocBackend
from tofnet.backends.registry import get_backend
from tofnet.backends.shared_bands import SharedBandKernel
from tofnet.backends.shared_memory import SharedBuffer, attach
from tofnet.compiler import compile_network
from tofnet.conformance.workers import first_difference
from tofnet.errors import BackendError
from tofnet.io.recording import Recording
from tofnet.networks import denoised_network, depth_network
from tofnet.testing import TEST_INTRINSICS, merge_events, moving_pattern, noise_events

SENSOR = (40, 30)
VELOCITY = {"source": "constant", "velocity": [-0.5, 0.2, 0.1], "per": "pixel"}
RECORDING = Recording(merge_events(moving_pattern(SENSOR, (300, -150), 200_000, seed=1),
                                   noise_events(SENSOR, 20, 200_000, seed=2)), intrinsics=TEST_INTRINSICS)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def shm():
    return sorted(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else []


def mapped_buffers(creator: int | None = None) -> list[str]:
    """Processes that still map one of tofnet's shared buffers (memfds named ``tofnet-*-PID``), of
    those ``creator`` made if given: other programs on the machine may run tofnet meanwhile."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/maps") as f:
                maps = f.read()
                if "memfd:tofnet" in maps if creator is None else re.search(rf"memfd:tofnet-\w+-{creator}\b", maps):
                    found.append(pid)
        except OSError:
            continue
    return found


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie is gone for our purposes
        return f.read().split(")")[-1].split()[0] != "Z"


def test_a_shared_buffer_is_never_in_dev_shm_and_maps_in_another_process():
    before = shm()
    buffer = SharedBuffer(4096)
    array = buffer.array("<i8")
    array[:3] = [7, 8, 9]
    mapped = attach(buffer.address)  # as a worker maps it (here: the same process)
    assert bytes(mapped[:8]) == (7).to_bytes(8, "little")
    assert not [name for name in set(shm()) - set(before) if "tofnet" in name]
    assert str(os.getpid()) in mapped_buffers()
    mapped.close()
    del array
    buffer.close()
    buffer.close()  # idempotent
    assert str(os.getpid()) not in mapped_buffers()


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_bands_on_worker_processes_equal_the_fixed_backend_and_per_core_mode_too(workers):
    compiled = compile_network(depth_network(SENSOR, input={"refractory": "1ms"}, velocity=VELOCITY), patch=(8, 8))
    fixed = get_backend("fixed").run(compiled, RECORDING, record_tot=True)
    with MultiprocBackend(workers=workers, packet_events=333).session() as session:
        banded = session.run(RECORDING, compiled=compiled, record_tot=True)
        assert banded.extra["shared_memory"] and len(banded.extra["bands"]) == workers
        assert first_difference(banded, fixed) == ""
        again = session.run(RECORDING, compiled=compiled, record_tot=True)  # the workers are kept
        assert first_difference(again, fixed) == ""
    per_core = MultiprocBackend(workers=workers, per_core=True).run(compiled, RECORDING, record_tot=True)
    assert "shared_memory" not in per_core.extra and first_difference(per_core, fixed) == ""


def test_the_workers_merge_into_the_runs_shared_result_which_grows_and_goes_with_its_array(monkeypatch):
    from tofnet.backends import local
    compiled = compile_network(depth_network(SENSOR, velocity=VELOCITY), patch=(8, 8))
    fixed = get_backend("fixed").run(compiled, RECORDING)
    monkeypatch.setattr(local, "RESULT_CAPACITY", 700)  # the result grows several times, as a long run's does
    targets = []
    target = SharedBandKernel._target
    monkeypatch.setattr(SharedBandKernel, "_target", lambda *a: targets.append(target(*a)) or targets[-1])
    with MultiprocBackend(workers=3, packet_events=500).session() as session:
        banded = session.run(RECORDING, compiled=compiled)
        assert first_difference(banded, fixed) == ""
        # every packet merged in place by the workers, in 3 buffers (the first, then grown twice)
        assert len(targets) == 45 and None not in targets and len({t[0] for t in targets}) == 3
        with open("/proc/self/maps") as f:  # the estimates are where the workers merged them
            assert f"memfd:tofnet-result-{os.getpid()}" in f.read()
    del banded
    gc.collect()
    assert str(os.getpid()) not in mapped_buffers()


def test_workers_share_the_cores_by_the_recordings_load_with_the_same_bytes():
    # events only in the lower rows: equal core counts would cut at row 16, the load at row 24
    compiled = compile_network(depth_network(SENSOR, input={"refractory": "1ms"}, velocity=VELOCITY), patch=(8, 8))
    low = Recording(RECORDING.events[RECORDING.events["y"] >= 16], intrinsics=TEST_INTRINSICS)
    fixed = get_backend("fixed").run(compiled, low, record_tot=True)
    with MultiprocBackend(workers=2, packet_events=333).session() as session:
        banded = session.run(low, compiled=compiled, record_tot=True)
    assert banded.extra["bands"] == [[0, 24], [24, 30]]
    assert first_difference(banded, fixed) == ""
    per_core = MultiprocBackend(workers=2, per_core=True).run(compiled, low, record_tot=True)
    assert first_difference(per_core, fixed) == ""


def test_a_packet_out_of_order_is_refused_by_every_worker_and_nothing_changes():
    network = depth_network(SENSOR, input={"refractory": "1ms"}, velocity=VELOCITY)
    events = RECORDING.events
    fixed = get_backend("fixed").run(network, RECORDING)
    stream = MultiprocBackend(workers=2).open_stream(network, recording=RECORDING)
    try:
        first = stream.feed_all(events[:700])
        bad = events[700:900].copy()
        bad["t"][120] = bad["t"][0] - 1
        with pytest.raises(BackendError, match="not sorted by time"):
            stream.feed_all(bad)
        rest = stream.feed_all(events[700:])
    finally:
        result = stream.close()
    got = np.concatenate([first["depth.depth"], rest["depth.depth"], result.outputs["depth.depth"]])
    assert got.tobytes() == fixed.depth.tobytes() and result.counts == fixed.counts


def test_other_graphs_run_per_core():
    compiled = compile_network(denoised_network(SENSOR, velocity=VELOCITY), patch=(8, 8))
    fixed = get_backend("fixed").run(compiled, RECORDING)
    result = MultiprocBackend(workers=2).run(compiled, RECORDING)
    assert "shared_memory" not in result.extra and first_difference(result, fixed) == ""


SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, {root!r})
    from tofnet.backends.multiproc import MultiprocBackend
    from tofnet.io.recording import Recording
    from tofnet.networks import depth_network
    from tofnet.testing import TEST_INTRINSICS, noise_events

    if __name__ == "__main__":
        recording = Recording(noise_events((240, 180), 200, 2_000_000, seed=3), intrinsics=TEST_INTRINSICS)
        network = depth_network((240, 180), velocity={{"source": "constant", "velocity": [0.5, 0, 0]}})
        with MultiprocBackend(workers=2, packet_events=4096).session() as session:
            print(*session.pids, flush=True)
            while True:
                session.run(recording, compiled=network)
""")


def test_kill_9_of_the_parent_mid_run_leaves_no_worker_and_nothing_in_dev_shm(tmp_path):
    script = tmp_path / "parent.py"
    script.write_text(SCRIPT.format(root=ROOT))
    before = shm()
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        pids = [int(p) for p in parent.stdout.readline().split()]
        assert len(pids) == 2
        time.sleep(1.0)  # into the runs; the parent maps its buffers during a run, not between two
        deadline = time.monotonic() + 30
        while str(parent.pid) not in mapped_buffers(parent.pid):
            assert time.monotonic() < deadline, "the parent never mapped a shared buffer"
            time.sleep(0.02)
        parent.send_signal(signal.SIGKILL)
        parent.wait(30)
        deadline = time.monotonic() + 30
        while any(alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(alive(p) for p in pids)
    finally:
        if parent.poll() is None:
            parent.kill()
    # the buffers were memfds: never in /dev/shm, and gone with the last process mapping them (other
    # programs on the machine may add their own entries to /dev/shm meanwhile: only tofnet's are checked)
    assert not [name for name in set(shm()) - set(before) if "tofnet" in name or name.startswith("memfd")]
    assert mapped_buffers(parent.pid) == []


def test_kill_9_of_a_worker_mid_run_is_reported_and_releases_the_buffers():
    compiled = compile_network(depth_network(SENSOR, velocity=VELOCITY), patch=(8, 8))
    with MultiprocBackend(workers=2, packet_events=100).session() as session:
        session.run(RECORDING, compiled=compiled)
        session._inject_fault(1, "kill")
        with pytest.raises(Exception, match="killed by signal 9"):
            session.run(RECORDING, compiled=compiled)
    assert str(os.getpid()) not in mapped_buffers()


@pytest.mark.parametrize("per_core", [False, True])
def test_a_streams_set_up_holds_the_workers_start_and_stop_not_its_network_time(per_core):
    """``tofnet run`` streams a recording that names its size: starting the workers (seconds) and stopping
    them are the stream's set-up, as for ``run``, never the network's time."""
    import time

    network = depth_network(SENSOR, input={"refractory": "1ms"}, velocity=VELOCITY)
    started = time.perf_counter()
    stream = MultiprocBackend(workers=2, per_core=per_core).open_stream(network, recording=RECORDING)
    stream.feed_all(RECORDING.events)
    result = stream.close()
    elapsed = time.perf_counter() - started
    startup = result.extra.get("startup_s") if not per_core else None
    assert result.setup_time >= max(0.3, startup or 0.0)  # spawning and warming up 2 workers: seconds
    assert result.wall_time + result.setup_time + result.compile_time <= elapsed + 1e-3  # nothing counted twice
