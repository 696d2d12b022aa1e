"""Workers for fixed and float: the sensor in bands of rows, byte-identical to one worker."""

import os

import numpy as np
import pytest

from tofnet import Session
from tofnet.backends import bands as bands_module
from tofnet.backends.bands import BandedKernel, resolve_workers
from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.backends.registry import get_backend
from tofnet.cli import main
from tofnet.compiler import compile_network
from tofnet.compiler.bands import input_reach, plan_bands
from tofnet.conformance.workers import check_workers, first_difference
from tofnet.errors import BackendError
from tofnet.events import EVENT_DTYPE, make_events
from tofnet.io.recording import Recording
from tofnet.networks import denoised_network, depth_network, improved_network
from tofnet.testing import TEST_INTRINSICS, merge_events, moving_pattern, noise_events

SENSOR = (24, 16)
VELOCITY = {"source": "constant", "velocity": [-0.5, 0.2, 0.1], "per": "pixel"}


def scene(sensor=SENSOR, seed=1):
    events = merge_events(moving_pattern(sensor, (300, -150), 100_000, seed=seed),
                          noise_events(sensor, 20, 100_000, seed=seed + 1))
    return Recording(events, intrinsics=TEST_INTRINSICS)


def with_bands(cls, bands, **options):
    """A backend whose bands are ``bands`` (rows), whatever the recording's load."""
    class Forced(cls):
        def _bands(self, network, known):
            return list(bands)
    return Forced(workers=len(bands), **options)


def edge_events(sensor, rows):
    """Events on exactly ``rows`` (band edges), both polarities, 3 events per pixel a step apart,
    plus events outside the sensor and before t0."""
    width, _ = sensor
    t, x, y, p = [], [], [], []
    for k in range(60):
        for row in rows:
            col = (3 * k + row) % width
            t += [1000 * k + row, 1000 * k + 400 + row]
            x += [col, (col + 1) % width]
            y += [row, row]
            p += [k % 2, 1 - k % 2]
    t += [0, 5000, 7000]
    x += [width + 3, 2, 1]
    y += [1, sensor[1] + 5, 2]
    p += [1, 0, 1]
    order = np.argsort(t, kind="stable")
    ev = make_events(np.array(t)[order], np.array(x)[order], np.array(y)[order], np.array(p)[order])
    return merge_events(ev, moving_pattern(sensor, (250, 200), 60_000, seed=4))


@pytest.mark.parametrize("cls", [FixedBackend, FloatBackend])
@pytest.mark.parametrize("bands", [
    [(0, 1), (1, 2), (2, 3), (3, 9), (9, 10), (10, 16)],  # bands of one row: narrower than the distance-2 halo
    [(0, 5), (5, 6), (6, 16)],
    [(0, 15), (15, 16)],
])
@pytest.mark.parametrize("fuse", [True, False])
def test_bands_narrower_than_the_halo_and_events_on_band_edges_change_nothing(cls, bands, fuse):
    network = depth_network(SENSOR, input={"refractory": "2ms"}, time_of_travel={"distance": 2}, velocity=VELOCITY)
    edges = sorted({b for band in bands for b in band if 0 < b < SENSOR[1]} | {b - 1 for band in bands for b in band
                                                                               if 0 < b < SENSOR[1]})
    recording = Recording(edge_events(SENSOR, edges), intrinsics=TEST_INTRINSICS)
    one = cls(fuse=fuse).run(network, recording, record_tot=True)
    banded = with_bands(cls, bands, fuse=fuse).run(network, recording, record_tot=True)
    assert len(one.depth) > 50 and one.dropped["out_of_bounds"] == 2 and one.dropped["before_t0"] == 0
    assert first_difference(banded, one) == ""
    assert banded.extra["bands"] == [list(b) for b in bands]


def test_a_band_without_events_and_packets_of_any_size():
    network = depth_network(SENSOR, velocity=VELOCITY)
    events = scene().events
    events = events[events["y"] < 8]  # the bottom half has no events
    recording = Recording(events, intrinsics=TEST_INTRINSICS)
    one = FixedBackend().run(network, recording, record_tot=True)
    for packet in (1, 7, 1000):
        banded = with_bands(FixedBackend, [(0, 4), (4, 8), (8, 12), (12, 16)], packet_events=packet)
        assert first_difference(banded.run(network, recording, record_tot=True), one) == ""


def test_a_stream_with_workers_returns_the_run_in_any_packets():
    network = depth_network(SENSOR, velocity=VELOCITY)
    recording = scene()
    one = FixedBackend().run(network, recording)
    stream = get_backend("fixed", workers=3).open_stream(network, recording=recording)
    assert isinstance(stream.kernel, BandedKernel)
    stream.kernel.one_band_below = 0  # bands even for these small packets
    events, parts = recording.events, []
    for lo in range(0, len(events), 97):
        parts.append(stream.feed_all(events[lo:lo + 97])["depth.depth"])
    result = stream.close()
    parts.append(result.outputs["depth.depth"])
    assert np.concatenate(parts).tobytes() == one.depth.tobytes()
    assert result.counts == one.counts and len(result.extra["bands"]) == 3
    assert not any(t.name.startswith("tofnet-band") and t.is_alive() for t in __import__("threading").enumerate())


def test_a_stream_fed_small_packets_keeps_one_band_and_returns_what_one_worker_returns():
    network = depth_network(SENSOR, velocity=VELOCITY)
    recording = scene()
    events = recording.events
    streams = [get_backend("fixed", workers=n).open_stream(network, recording=recording) for n in (1, 2)]
    for lo in range(0, len(events), 50):  # feed (not feed_all): the trigger events' order, as one worker's
        a, b = (s.feed(events[lo:lo + 50]) for s in streams)
        assert a.tobytes() == b.tobytes()
    one, two = (s.close() for s in streams)
    assert two.counts == one.counts and two.extra["bands"] == [[0, SENSOR[1]]]


def test_a_stream_whose_first_packet_is_large_runs_bands():
    network = depth_network(SENSOR, velocity=VELOCITY)
    recording = scene()
    events = recording.events
    copies = -(-bands_module.FUSED_BANDS_FROM // len(events))
    span = int(events["t"][-1]) + 1
    packet = np.concatenate([events[["t", "x", "y", "p"]] for _ in range(copies)])  # time order: shifted below
    packet["t"] += np.repeat(np.arange(copies) * span, len(events))
    assert len(packet) >= bands_module.FUSED_BANDS_FROM
    streams = [get_backend("fixed", workers=n).open_stream(network, recording=recording) for n in (1, 2)]
    a, b = (s.feed_all(packet) for s in streams)
    assert a["depth.depth"].tobytes() == b["depth.depth"].tobytes() and len(a["depth.depth"])
    one, two = (s.close() for s in streams)
    assert two.counts == one.counts and len(two.extra["bands"]) == 2


@pytest.fixture(params=["serial", "threads"])
def hand_over(request, monkeypatch):
    """Bands of a small packet run one after the other in the caller's thread (``serial``); ``threads``
    hands them to the pool as large packets are (every packet, however small)."""
    if request.param == "threads":
        monkeypatch.setattr(bands_module, "SERIAL_BELOW", 0)
    return request.param


def test_a_stream_refuses_a_packet_out_of_order_and_stays_as_it_was(hand_over):
    network = depth_network(SENSOR, velocity=VELOCITY)
    recording = scene()
    events = recording.events
    stream = get_backend("fixed", workers=2).open_stream(network, recording=recording)
    stream.kernel.one_band_below = 0
    first = stream.feed_all(events[:500])
    bad = events[500:600].copy()
    bad["t"][50] = bad["t"][0] - 1
    with pytest.raises(BackendError, match="not sorted by time"):
        stream.feed_all(bad)
    rest = stream.feed_all(events[500:])
    result = stream.close()
    one = FixedBackend().run(network, recording)
    got = np.concatenate([first["depth.depth"], rest["depth.depth"], result.outputs["depth.depth"]])
    assert got.tobytes() == one.depth.tobytes() and result.counts == one.counts


def test_sessions_gather_and_scatter_variables_across_bands():
    compiled = compile_network(denoised_network(SENSOR, input={"refractory": "1ms"}, denoise={"window": "4ms"},
                                                velocity=VELOCITY), patch=(8, 8))
    recording = scene()
    names = ["input.last_accepted", "denoise.last_spike", "time_of_travel.counter", "depth.a_t"]
    with Session(compiled, recording, backend="fixed") as one, \
            Session(compiled, recording, backend="fixed", backend_options={"workers": 3}) as three:
        for steps in (13, 40):
            one.run(steps=steps)
            three.run(steps=steps)
            for name in names:
                assert np.array_equal(one.get(name), three.get(name)), name
        counter = one.get("time_of_travel.counter")
        counter[0, 3:9, 4] = 2
        one.set("time_of_travel.counter", counter)
        three.set("time_of_travel.counter", counter)
        assert np.array_equal(three.get("time_of_travel.counter"), counter)
        a, b = one.finish(), three.finish()
    assert first_difference(b, a) == ""


def test_processes_that_cannot_hold_a_region_run_whole_and_the_result_says_so():
    network = improved_network(SENSOR, velocity=VELOCITY)
    recording = scene()
    one = FixedBackend().run(network, recording)
    two = FixedBackend(workers=2).run(network, recording)
    assert first_difference(two, one) == ""
    # the velocity process (host, broadcast) runs whole; the time surface runs in bands (test_bands_time_surface)
    assert two.extra["whole"] == ["velocity"] and two.extra["banded"] == ["time_surface"]


def test_auto_workers_are_the_cpus_this_process_may_use_not_the_hosts(monkeypatch):
    """In a container or a Slurm job given 2 of a host's 64 CPUs, 'auto' makes 2 bands and threads, not 64."""
    from tofnet.backends.bands import threads_for
    from tofnet.backends.multiproc import MultiprocBackend
    monkeypatch.setattr(os, "cpu_count", lambda: 64)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3, 5}, raising=False)
    assert resolve_workers("auto") == resolve_workers(0) == 2 and threads_for(16) == 2
    assert MultiprocBackend().workers == MultiprocBackend(workers="auto").workers == 2


def test_workers_option_and_its_errors(capsys, tmp_path):
    from tofnet.machine import cpu_count
    cpus = cpu_count()
    assert resolve_workers(0) == resolve_workers("auto") == cpus and resolve_workers(None) == 1
    assert FixedBackend(workers=7).workers == 7 and get_backend("float", workers="auto").workers == cpus
    for bad in (-1, 1.5, "many", True):
        with pytest.raises(BackendError, match="workers"):
            FixedBackend(workers=bad)
    np.save(tmp_path / "ev.npy", scene().events)
    assert main(["run", str(tmp_path / "ev.npy"), "--workers", "lots", "--out", str(tmp_path / "d.npz"),
                 "--velocity", "0.5,0,0", "--quiet"]) != 0
    assert "--workers" in capsys.readouterr().err


def test_bands_are_balanced_by_load_and_the_reach_composes():
    load = np.zeros(100)
    load[:10] = 50  # the busy top rows get narrow bands
    load[10:] = 1
    bands = plan_bands(100, 4, load)
    assert bands[0][0] == 0 and bands[-1][1] == 100 and all(a[1] == b[0] for a, b in zip(bands, bands[1:]))
    assert bands[0][1] - bands[0][0] < 10 < bands[-1][1] - bands[-1][0]
    assert plan_bands(3, 7) == [(0, 1), (1, 2), (2, 3)]  # never more bands than rows
    assert plan_bands(10, 3) == [(0, 3), (3, 7), (7, 10)]
    assert input_reach(depth_network(SENSOR, time_of_travel={"distance": 2})) == 2
    denoised = denoised_network(SENSOR, denoise={"radius": 1}, time_of_travel={"distance": 2})
    assert input_reach(denoised) == 3  # halos compose along the chain


@pytest.mark.parametrize("backend", ["fixed", "float"])
def test_every_conformance_case_is_byte_identical_on_1_2_3_and_7_workers(backend):
    results = check_workers(backend, (1, 2, 3, 7))
    failed = [f"{r.case} {r.mode}: {r.first}" for r in results if not r.ok]
    assert results and not failed, failed


def test_events_outside_the_sensor_count_once(hand_over):
    network = depth_network(SENSOR, velocity=VELOCITY)
    events = np.zeros(5, EVENT_DTYPE)
    events["t"] = [0, 1, 2, 3, 4]
    events["x"] = [1, 30, 2, 500, 3]
    events["y"] = [1, 2, 40, 3, 15]  # x 30, 500: rows in two bands' halos; y 40: below the sensor
    recording = Recording(events, intrinsics=TEST_INTRINSICS)
    result = with_bands(FixedBackend, [(0, 2), (2, 9), (9, 16)]).run(network, recording)
    assert result.dropped["out_of_bounds"] == 3 and result.accepted == 2 and result.events_in == 5


@pytest.mark.parametrize("bands", [[(0, 8), (8, 16)], [(0, 1), (1, 2), (2, 3), (3, 9), (9, 10), (10, 16)]])
def test_packets_handed_to_threads_equal_one_worker(hand_over, bands):
    """Every band lists its events of the packet and runs them on the pool's threads; the estimates
    are merged by shares of the steps, each share on a thread."""
    network = depth_network(SENSOR, input={"refractory": "2ms"}, time_of_travel={"distance": 2}, velocity=VELOCITY)
    recording = Recording(edge_events(SENSOR, range(SENSOR[1])), intrinsics=TEST_INTRINSICS)
    one = FixedBackend().run(network, recording, record_tot=True)
    for packet in (50, 4096):
        banded = with_bands(FixedBackend, bands, packet_events=packet).run(network, recording, record_tot=True)
        assert first_difference(banded, one) == ""
    assert len(one.depth) > 200


def test_a_packet_in_threads_is_one_hand_over_and_every_thread_touches_fresh_output(monkeypatch):
    """Bands and merge in one hand-over per packet (a barrier between them); the first touch of the
    output's fresh pages is shared by the threads, by huge-page blocks."""
    monkeypatch.setattr(bands_module, "SERIAL_BELOW", 0)
    network = depth_network(SENSOR, velocity=VELOCITY)
    stream = get_backend("fixed", workers=2).open_stream(network, recording=scene())
    stream.kernel.one_band_below = 0
    stream.feed_all(scene().events[:300])  # builds the bands
    calls, touched = [], []
    run, touch = bands_module.BandPool.run, bands_module.touch
    monkeypatch.setattr(bands_module.BandPool, "run", lambda pool, *a: calls.append(a[1]) or run(pool, *a))
    monkeypatch.setattr(bands_module, "touch", lambda *a: touched.append(a[4:6]) or touch(*a))
    into = np.empty(1 << 18, stream.kernel.buffers()[0].dtype)  # fresh: 7 MB
    stream.kernel.run_events(scene().events[300:2000], stream._updates.rows, into, 0)
    assert calls == [2] and sorted(touched) == [(0, 2), (1, 2)]

    raw = np.ones(5 << 21, np.uint8)
    address = raw.ctypes.data
    for part in (0, 1):
        bands_module.touch(raw, address, 100, len(raw) - 100, part, 2, 1 << 21)
    pages = np.flatnonzero(raw == 0)
    assert np.all((address + pages) % 4096 == 0) and len(pages) == np.sum((address + np.arange(100, len(raw) - 100))
                                                                          % 4096 == 0)


def test_tofnet_run_with_workers_writes_the_same_bytes_and_says_how_it_split(tmp_path, capsys):
    np.save(tmp_path / "ev.npy", scene((60, 40)).events)
    common = ["--velocity", "0.5,0,0", "--intrinsics", "200,200,30,20", "--quiet"]
    for estimator in ("paper", "improved"):
        outs = []
        for workers in ("1", "3"):
            out = tmp_path / f"{estimator}-{workers}.npz"
            assert main(["run", str(tmp_path / "ev.npy"), "--estimator", estimator, "--workers", workers,
                         "--out", str(out), *common]) == 0
            outs.append(out.read_bytes())
        assert outs[0] == outs[1]
        text = capsys.readouterr().out
        assert "workers        3 bands of rows on " in text
        assert ("run whole:" in text) == (estimator == "improved")


def test_a_batch_grid_of_workers_runs_each_task_with_them_and_the_same_counts(tmp_path):
    from tofnet.batch import PlanError, expand, load_plan
    from tofnet.batch.worker import run_task

    np.save(tmp_path / "ev.npy", scene((60, 40)).events)
    (tmp_path / "plan.yaml").write_text("recordings:\n  - {path: ev.npy, intrinsics: '200,200,30,20'}\n"
                                        "velocity: [0.5, 0, 0]\ngrid:\n  workers: [1, 3]\n")
    tasks = expand(load_plan(tmp_path / "plan.yaml"))
    assert [t.parameters for t in tasks] == [{"workers": 1}, {"workers": 3}]
    rows = [run_task(task) for task in tasks]
    assert all(r["status"] == "ok" for r in rows), rows
    assert rows[0]["depth_out"] == rows[1]["depth_out"] > 0 and rows[0]["events_in"] == rows[1]["events_in"]
    (tmp_path / "plan.yaml").write_text("recordings: [ev.npy]\ngrid:\n  workers: [1, lots]\n")
    with pytest.raises(PlanError, match=r"grid.workers\[1\]: 'lots'.*whole number of workers"):
        load_plan(tmp_path / "plan.yaml")


def test_a_regions_table_of_kinds_marks_its_pixels_and_its_halo_and_nothing_else():
    from tofnet.kernels.kernel_config import COLUMNS, Region

    x0, y0, x1, y1, d = 3, 0, 24, 7, 2
    table = Region(x0, x1, y0, y1).kinds(d)
    xs, ys = np.meshgrid(np.arange(40), np.concatenate([np.arange(12), [65535]]))
    kind = table[ys] & table[COLUMNS + xs]
    own = (x0 <= xs) & (xs < x1) & (y0 <= ys) & (ys < y1)
    halo = (x0 - d <= xs) & (xs < x1 + d) & (y0 - d <= ys) & (ys < y1 + d)
    assert np.array_equal(kind > 1, own) and np.array_equal(kind != 0, halo)


def test_run_with_workers_feeds_larger_packets_and_gives_the_same_outputs():
    """Several workers run in packets of 2^19 events (one hand-over and one wait per packet), one worker
    in packets of 2^17, unless the user asks for a size; the outputs do not depend on it."""
    sensor = (64, 48)
    events = merge_events(moving_pattern(sensor, (300, -150), 400_000, seed=3),
                          noise_events(sensor, 400, 400_000, seed=5))
    assert len(events) > 1 << 19
    recording = Recording(events, intrinsics=TEST_INTRINSICS)
    network = depth_network(sensor, velocity=VELOCITY)
    seen = {}
    for workers in (1, 2):
        calls = []
        result = FixedBackend(workers=workers).run(network, recording, progress=lambda d, t: calls.append(d))
        seen[workers] = (calls, result)
    assert seen[1][0][0] == 1 << 17 and seen[2][0][0] == 1 << 19
    assert seen[2][0][-1] == seen[1][0][-1] == len(events)
    assert sum(len(out) for out in seen[1][1].outputs.values()) > 1000  # estimates to compare
    assert first_difference(seen[2][1], seen[1][1]) == ''
    assert FixedBackend(workers=2, packet_events=1000).packet_events == 1000
