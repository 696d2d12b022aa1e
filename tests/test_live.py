"""tofnet live: replay at the recorded speed, the delay of each estimate, late packets, PNG frames, cameras."""

import time
from pathlib import Path

import numpy as np
import pytest

from formats_helpers import pattern_recording
from optional import optional
from tofnet.api import run as run_recording
from tofnet.cli import main
from tofnet.errors import TofnetError
from tofnet.events import EVENT_DTYPE
from tofnet.io.arrays import write_npz_recording
from tofnet.io.source import open_recording
from tofnet.live import CameraSource, ReplaySource, packet_bounds, run_live
from tofnet.networks import depth_network

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "real"  # ../shared/real beside the checkout
SPAN_S = 0.2


@pytest.fixture(scope="module")
def recording_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("live") / "pattern.npz"
    write_npz_recording(path, pattern_recording(int(SPAN_S * 1e6)))
    return path


def _network(source):
    return depth_network(source.sensor_size)


def test_packets_split_at_every_step():
    t = np.array([5, 999, 1000, 1001, 3500], dtype=np.int64)
    cuts, ends = packet_bounds(t, 0, 1000)
    assert list(ends) == [1000, 2000, 3000, 4000] and list(cuts) == [0, 2, 4, 4, 5]


@pytest.mark.parametrize("speed", [1.0, 2.0])
def test_replay_takes_the_recordings_time_and_every_delay_is_real(recording_file, speed):
    with open_recording(recording_file) as source:
        span_s = (source.read().events["t"][-1] - source.first_time()) * 1e-6
        replay = ReplaySource(source, speed=speed)
        started = time.perf_counter()
        stats, result = run_live(replay, _network(source), backend="fixed")
        took = time.perf_counter() - started
    # Paced by the file's clock: never faster than the recording, not much slower on an idle machine.
    assert stats.wall_s >= 0.95 * span_s / speed and stats.speed == speed  # the cpu share is of that wall time
    assert took < span_s / speed + 30  # generous: the session's warm-up and a loaded machine
    assert stats.events_in == len(open_recording(recording_file).read().events)
    assert stats.packets == int(np.ceil(stats.span_us / 1000))
    # every estimate is counted; the delays are those of the estimates handed back while the source ran
    assert stats.depth_out >= stats.delays.count > 0
    # An estimate is handed back only once its step is complete on the replay clock: at least
    # latency + 1 steps after its event's step began.
    assert stats.delays.min_us >= 3000
    assert stats.percentile_ms(50) <= stats.percentile_ms(99)


def test_live_estimates_equal_a_whole_run(recording_file):
    with open_recording(recording_file) as source:
        whole = source.read()
        network = _network(source)
        seen = []
        stats, result = run_live(ReplaySource(source, speed=4.0), network, backend="fixed", on_depth=seen.append)
    reference, _ = run_recording(whole, network, backend="fixed")
    name = result.depth_outputs[0]
    live = np.concatenate(seen)
    assert len(live) > 0 and stats.depth_out == len(live) == len(reference.outputs[name])  # the last steps' too
    assert np.array_equal(np.sort(live, order=["t", "x", "y"]), np.sort(reference.outputs[name], order=["t", "x", "y"]))
    assert result.counts == reference.counts
    assert len(result.outputs[name]) < len(live)  # the session kept none of the estimates handed over


class _BehindSource:
    """A source whose clock is always far ahead: every packet is late."""
    packet_us, t0_us = 1000, 0

    def __init__(self, sizes):
        self.sizes = sizes

    def packets(self):
        for i, n in enumerate(self.sizes):
            events = np.zeros(n, EVENT_DTYPE)
            events["t"] = i * 1000 + np.arange(n) % 1000
            yield events, (i + 1) * 1000

    def now_us(self):
        return 1e12


@pytest.mark.parametrize("batch, drop", [(True, False), (False, False), (True, True)])
def test_a_late_run_catches_up_in_batches_only_where_bands_pay(batch, drop):
    from tofnet.live import CATCH_UP_EVENTS, LiveStats, catching_up
    sizes = [5, 0, 7, CATCH_UP_EVENTS, 3, 4]
    stats = LiveStats()
    fed = list(catching_up(_BehindSource(sizes), stats, drop, lambda: batch))
    assert stats.packets == len(sizes) and stats.late_packets == len(sizes)
    if drop:
        assert [len(e) for e, _ in fed] == [0] * len(sizes) and stats.dropped_events == sum(sizes)
    elif batch:  # the packets complete behind a late one come with it, up to CATCH_UP_EVENTS events
        assert [(len(e), until) for e, until in fed] == [(5 + 0 + 7 + CATCH_UP_EVENTS, 4000), (7, 6000)]
        assert stats.batches == 2
        assert np.array_equal(np.concatenate([e["t"] for e, _ in fed]),
                              np.concatenate([e["t"] for e, _ in _BehindSource(sizes).packets()]))
    else:
        assert [len(e) for e, _ in fed] == sizes and stats.batches == 0


class _ScriptedLag:
    """Packets of 10 events, each fed ``behind_ms[i]`` after it was complete."""
    packet_us, t0_us = 1000, 0

    def __init__(self, behind_ms):
        self.behind_ms, self.now = behind_ms, 0.0

    def packets(self):
        for i, behind in enumerate(self.behind_ms):
            events = np.zeros(10, EVENT_DTYPE)
            events["t"] = i * 1000 + np.arange(10)
            self.now = (i + 1) * 1000 + behind * 1000
            yield events, (i + 1) * 1000

    def now_us(self):
        return self.now


def test_drop_when_late_drops_only_the_packets_beyond_the_tolerance():
    """One packet late dropped a whole packet: at 20 M events/s only 0.2-10 % of the events were fed, at
    0.25x (keeping up) 3-12 % were dropped, 14-19 % of the real EVT3 at 1x using 20 % of a core."""
    from tofnet.live import LiveStats, catching_up
    behind = [0.5, 2, 10, 60, 150, 99, 101, 2]  # ms
    stats = LiveStats()
    fed = [len(e) for e, _ in catching_up(_ScriptedLag(behind), stats, True, lambda: False)]
    assert fed == [10, 10, 10, 10, 0, 10, 0, 10]  # the default: dropped beyond 100 ms
    assert (stats.late_packets, stats.dropped_packets, stats.dropped_events) == (7, 2, 20)  # every drop counted
    stats = LiveStats()
    fed = [len(e) for e, _ in catching_up(_ScriptedLag(behind), stats, True, lambda: False, late_tolerance_us=5000)]
    assert fed == [10, 10, 0, 0, 0, 0, 0, 10] and stats.dropped_events == 50


def test_cli_late_tolerance_is_said_and_needs_drop_when_late(recording_file, tmp_path, capsys):
    import json
    assert main(["live", "--replay", str(recording_file), "--late-tolerance", "5ms"]) == 2
    assert capsys.readouterr().err.strip() == ("tofnet live: error: --late-tolerance: expected with --drop-when-late "
                                               "(it says when a late packet is dropped)")
    assert main(["live", "--replay", str(recording_file), "--drop-when-late", "--late-tolerance", "-1ms"]) == 2
    assert "expected a time of 0 s or more, got -1ms" in capsys.readouterr().err
    out = tmp_path / "s.json"
    assert main(["live", "--replay", str(recording_file), "--speed", "8", "--velocity", "0,0,1", "--no-view",
                 "--drop-when-late", "--late-tolerance", "5ms", "--json", str(out)]) == 0
    stats = json.loads(out.read_text())
    assert stats["late_tolerance_ms"] == 5 and stats["events_in"] + stats["dropped_events"] == len(
        open_recording(recording_file).read().events)


def test_a_banded_time_surface_behind_catches_up_with_the_estimates_of_a_run(recording_file):
    from tofnet.networks import improved_network
    with open_recording(recording_file) as source:
        whole = source.read()
        network = improved_network(source.sensor_size)
        seen = []
        stats, result = run_live(ReplaySource(source, speed=200.0), network, backend="fixed",
                                 backend_options={"workers": 2}, on_depth=seen.append)
    reference, _ = run_recording(whole, network, backend="fixed")
    name = result.depth_outputs[0]
    live = np.concatenate(seen)
    assert stats.batches > 0 and len(live) > 0  # at 200x the recorded speed it falls behind and batches
    assert np.array_equal(np.sort(live, order=["t", "x", "y"]), np.sort(reference.outputs[name], order=["t", "x", "y"]))
    assert result.counts == reference.counts


def test_falling_behind_is_measured_and_drops_only_when_asked(recording_file):
    slow = lambda: time.sleep(0.003)  # noqa: E731 - a display that takes 3 ms per 1 ms packet
    with open_recording(recording_file) as source:
        total = len(source.read().events)
        kept, _ = run_live(ReplaySource(source), _network(source), backend="fixed", tick=slow)
    assert kept.late_packets > 0 and kept.max_behind_us > 50_000
    assert kept.dropped_events == 0 and kept.events_in == total
    with open_recording(recording_file) as source:
        dropped, _ = run_live(ReplaySource(source), _network(source), backend="fixed", tick=slow,
                              drop_when_late=True)
    assert dropped.dropped_events > 0 and dropped.dropped_packets > 0
    assert dropped.events_in + dropped.dropped_events == total
    assert dropped.depth_out < kept.depth_out  # what was dropped was not estimated


class _Packets:
    """A recording's 1 ms packets on its own clock (never late); a ``KeyboardInterrupt`` instead of packet
    ``interrupt_at`` (a second Ctrl-C while waiting for a camera)."""
    packet_us = 1000

    def __init__(self, recording, count: int, interrupt_at: int | None = None):
        self.recording, self.count, self.interrupt_at = recording, count, interrupt_at
        self.t0_us, self.now = int(recording.events["t"][0]), 0.0

    def metadata(self):
        return self.recording

    def now_us(self):
        return self.now

    def packets(self):
        t = self.recording.events["t"]
        for i in range(self.count):
            if i == self.interrupt_at:
                raise KeyboardInterrupt
            start = self.t0_us + 1000 * i
            self.now = start + 1000
            yield self.recording.events[np.searchsorted(t, start):np.searchsorted(t, start + 1000)], start + 1000


def test_ctrl_c_while_waiting_for_a_packet_ends_the_run_as_the_source_s_end_does():
    recording = pattern_recording(int(SPAN_S * 1e6))
    network = _network(recording)
    try:
        stopped, stopped_result = run_live(_Packets(recording, 150, interrupt_at=60), network, backend="fixed")
    except KeyboardInterrupt:
        pytest.fail("the KeyboardInterrupt escaped run_live: the figures of the run up to it are lost")
    ended, ended_result = run_live(_Packets(recording, 60), network, backend="fixed")
    assert stopped.interrupted and not ended.interrupted
    assert stopped.packets == ended.packets == 60 and stopped.events_in == ended.events_in
    assert stopped.depth_out == ended.depth_out > 0 and stopped_result.counts == ended_result.counts
    assert stopped.lines()[-1] == "ended          by Ctrl-C: these figures cover the run up to it"


def test_bad_speed_is_one_line(recording_file):
    with open_recording(recording_file) as source, pytest.raises(TofnetError, match="--speed"):
        ReplaySource(source, speed=0)


class _FakeCamera:
    """faery's camera stream: packets of any length in faery's dtype, times on the camera's clock."""

    def __init__(self, events):
        import faery
        self.packets = []
        for part in np.array_split(events, 7):
            raw = np.empty(len(part), faery.EVENTS_DTYPE)
            raw["t"], raw["x"], raw["y"], raw["on"] = part["t"], part["x"], part["y"], part["p"] == 1
            self.packets.append(raw)

    def dimensions(self):
        return (64, 48)

    def __iter__(self):
        yield from self.packets


def test_camera_packets_are_whole_steps_in_order():
    optional("faery")
    events = pattern_recording(50_000).events
    camera = CameraSource(opener=lambda: _FakeCamera(events))
    assert camera.metadata().sensor_size == (64, 48)
    got = list(camera.packets())
    t, start = events["t"], int(events["t"][0])
    last_step = (int(t[-1]) - start) // 1000
    # One packet per 1 ms step from the first event (empty ones too), each exactly that step's events...
    assert [end for _, end in got] == [start + 1000 * k for k in range(1, last_step + 1)]
    for packet, end in got:
        assert np.array_equal(packet, events[(t >= end - 1000) & (t < end)])
    # ...except the last step, which may still receive events: held back.
    out = np.concatenate([p for p, _ in got])
    assert np.array_equal(out, events[t < start + 1000 * last_step]) and len(out) < len(events)


def test_no_camera_is_one_line(capsys):
    optional("faery")
    import importlib.util
    if importlib.util.find_spec("neuromorphic_drivers") or importlib.util.find_spec("event_camera_drivers"):
        pytest.skip("camera drivers installed: a camera may be present")
    assert main(["live", "--camera"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no event camera found" in err


def test_cli_replay_writes_png_frames_atomically(recording_file, tmp_path, capsys):
    out = tmp_path / "frames"
    assert main(["live", "--replay", str(recording_file), "--speed", "2", "--velocity", "0,0,1", "--out", str(out),
                 "--png-every", "0.05s", "--json", str(tmp_path / "stats.json")]) == 0
    text = capsys.readouterr().out
    assert "delay          p50" in text and "p99" in text and "PNG frames" in text
    frames = sorted(p.name for p in out.iterdir() if p.name != ".tofnet-manifest.json")
    assert frames and all(name.startswith("depth-") and name.endswith(".png") for name in frames)
    import json
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["delay_p99_ms"] >= stats["delay_p50_ms"] >= 3.0
    (out / "notes.txt").write_text("mine")
    assert main(["live", "--replay", str(recording_file), "--out", str(out)]) == 2
    assert "did not write" in capsys.readouterr().err and (out / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("backend", ["fixed", "multiproc"])
@pytest.mark.parametrize("rotation", [True, False])  # eq. 7 runs model by model; without it the chain is fused
def test_cli_live_on_two_workers_hands_back_what_one_worker_does(recording_file, tmp_path, backend, rotation, capsys):
    import json
    stats = {}
    for workers in ("1", "2"):
        out = tmp_path / f"{backend}-{workers}.json"
        assert main(["live", "--replay", str(recording_file), "--speed", "4", "--velocity", "0,0,1", "--no-view",
                     "--backend", backend, "--workers", workers, "--json", str(out)]
                    + ([] if rotation else ["--no-rotation"])) == 0
        stats[workers] = json.loads(out.read_text())
        text = capsys.readouterr().out
        if backend == "fixed" and rotation:  # how the work was split, when it was
            assert ("workers        2 bands of rows on 2 threads" in text) == (workers == "2")
        if backend == "fixed" and not rotation and workers == "2":  # 1 ms packets: one band, and why
            assert "workers        1 band of rows on 1 thread; one band: the first packet held " in text
    assert stats["1"]["depth_out"] == stats["2"]["depth_out"] > 0
    assert stats["1"]["events_in"] == stats["2"]["events_in"]


@pytest.mark.skipif(not (REAL / "evt3.raw").is_file(),
                    reason="needs the real EVT3 recording, not distributed with tofnet (shared/real/ beside the checkout)")
def test_real_evt3_window_replays_in_step_with_its_clock():
    optional("faery")
    from tofnet.io.calibration import parse_intrinsics
    from tofnet.io.window import parse_window

    window = parse_window("2s", "0.3s", None)
    with open_recording(REAL / "evt3.raw", intrinsics=parse_intrinsics("1000,1000,640,360"), window=window) as source:
        expected = len(open_recording(REAL / "evt3.raw", window=window).read().events)
        network = depth_network(source.sensor_size)
        from tofnet.api import constant_velocity
        constant_velocity(network, "0,0,1")
        stats, _ = run_live(ReplaySource(source), network, backend="fixed")
    assert stats.events_in == expected > 10_000
    assert stats.wall_s >= 0.95 * 0.3 and abs(stats.span_us * 1e-6 - 0.3) < 0.002
    assert stats.depth_out > 0 and stats.delays.min_us >= 3000
    assert np.isfinite(stats.percentile_ms(99))


def test_a_png_frame_is_written_beside_the_packets_not_between_them(tmp_path, monkeypatch):
    """Frames written in line took the p99 delay of a 1280x720 replay from 5 to 107 ms; now the packets'
    thread only copies the map, and a frame due while the previous one is written is skipped (counted)."""
    import time

    from tofnet import live_view
    from tofnet.live_view import DepthMap, PngFolder

    write = live_view.palette_png

    def slow(*args, **kwargs):
        time.sleep(0.6)
        write(*args, **kwargs)

    monkeypatch.setattr(live_view, "palette_png", slow)
    depth = DepthMap((64, 48))
    depth.add(np.array([(1000, 3, 4, 1.5)], dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("z", "<f8")]))
    frames = PngFolder(tmp_path / "frames", depth, every_s=0.0)
    started = time.perf_counter()
    frames.tick()
    frames.tick()  # the first is still being written: skipped
    assert time.perf_counter() - started < 0.3 and frames.skipped == 1  # not the 0.6 s of a frame
    assert frames.close().endswith("(1 skipped: the previous one was still being written)")
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == ["depth-000001.png", "depth-000002.png"]


def test_a_recording_with_a_gyroscope_replays_as_it_runs(tmp_path):
    """The default network of a recording with an IMU reads its gyroscope (eq. 7); the live session was told
    only the intrinsics and poses, so it could not start ('no IMU samples')."""
    from tofnet.api import default_network
    from tofnet.io.ecd import write_ecd
    from tofnet.io.recording import Intrinsics
    from tofnet.io.rotation import write_imu

    recording = pattern_recording(int(SPAN_S * 1e6))
    folder = tmp_path / "rec"
    write_ecd(folder, recording.events, intrinsics=Intrinsics(50.0, 50.0, 12.0, 8.0), sensor_size=recording.sensor_size)
    t = np.arange(-0.01, SPAN_S + 0.02, 0.005) + recording.events["t"][0] * 1e-6
    write_imu(folder / "imu.txt", t, np.zeros((len(t), 3)), np.tile([0.0, -0.2, 0.0], (len(t), 1)))
    with open_recording(folder) as source:
        whole = source.read()
        network = default_network(whole)
        from tofnet.api import constant_velocity
        constant_velocity(network, "0.3,0,0")
        assert network.process("angular_velocity").source == "gyro"
        seen = []
        stats, result = run_live(ReplaySource(source, speed=4.0), network, backend="fixed", on_depth=seen.append)
    reference, _ = run_recording(whole, network, backend="fixed")
    assert result.counts == reference.counts and result.counts["depth"]["emitted"] > 0


def test_cli_live_takes_what_run_takes_a_window_and_the_sensor_size(tmp_path, capsys):
    """live reads a file as tofnet run does (its sensor size, what falls outside it counted) and a time window
    starts its steps at the window's first event, as tofnet run does: the same estimates and counts."""
    from tofnet.io.events import write_events_npy

    events = pattern_recording(int(SPAN_S * 1e6)).events.copy()
    events["x"][::7] += 230  # some beyond the 240x180 a network takes when nothing says the size
    bare = tmp_path / "bare.npy"
    write_events_npy(bare, events)
    camera = ["--velocity", "0.5,0.1,0", "--intrinsics", "200,200,120,30"]
    for window in ([], ["--start", "0.0123s", "--duration", "0.3s"]):
        seen = {}
        for command in (["run", str(bare), "--out", str(tmp_path / "d.npz"), "--force"],
                        ["live", "--replay", str(bare), "--no-view", "--speed", "8"]):
            assert main([*command, *camera, *window]) == 0
            out = capsys.readouterr().out
            depth = next(line for line in out.splitlines() if line.startswith("depth out")).split()[2]
            dropped = next(line for line in out.splitlines() if line.endswith("out of bounds")).split()[1]
            seen[command[0]] = (depth, dropped)
        assert seen["run"] == seen["live"] and seen["run"][0] != "0" and seen["run"][1] != "0", (window, seen)


@pytest.mark.skipif(not (REAL / "evt2.raw").is_file(),
                    reason="needs the real EVT2 recording, not distributed with tofnet (shared/real/ beside the checkout)")
def test_cli_live_sizes_a_file_without_its_geometry_by_its_events_as_run_does(capsys):
    optional("faery")
    camera = ["--velocity", "0.5,0,0", "--intrinsics", "500,500,320,240"]
    assert main(["live", "--replay", str(REAL / "evt2.raw"), "--no-view", "--speed", "8", *camera]) == 0
    out = capsys.readouterr().out
    assert "640x480 px" in out and "taken from the events' extent" in out
