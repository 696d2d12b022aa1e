"""`tofnet run` streams a file through the network: bounded memory, the same bytes as a whole read."""

import tracemalloc

import numpy as np

from tofnet.api import run, run_source
from tofnet.cli import main
from tofnet.events import EVENT_DTYPE
from tofnet.io import read_recording
from tofnet.io.recording import Intrinsics, Recording
from tofnet.io.source import open_recording
from tofnet.networks import depth_network
from tofnet.testing import merge_events, moving_pattern, noise_events
from optional import optional

optional("h5py")
from tofnet.io.hdf5 import write_hdf5  # noqa: E402

SENSOR = (64, 48)
INTRINSICS = Intrinsics(80.0, 80.0, 31.5, 23.5)
NET = dict(velocity={"source": "constant", "velocity": [-0.4, 0.1, 0.05]})


def write_file(path, seconds: int) -> int:
    def chunks():
        for s in range(seconds):
            part = merge_events(moving_pattern(SENSOR, (300, -120), 1_000_000, seed=s),
                                noise_events(SENSOR, 20, 1_000_000, seed=s))
            part["t"] += s * 1_000_000
            yield part
    return write_hdf5(path, chunks(), Recording(np.empty(0, EVENT_DTYPE), intrinsics=INTRINSICS, sensor_size=SENSOR))


def test_a_streamed_file_gives_exactly_the_run_of_the_whole_recording(tmp_path):
    path = tmp_path / "rec.h5"
    write_file(path, 2)
    whole, _ = run(read_recording(path), depth_network(SENSOR, **NET), record_tot=True)
    with open_recording(path) as source:
        streamed, _ = run_source(source, depth_network(SENSOR, **NET), record_tot=True, spill_dir=tmp_path,
                                 spill_bytes=100_000, chunk_events=30_000)
    assert isinstance(streamed.depth, np.memmap) and len(streamed.depth) > 10_000  # spilled to disk
    assert streamed.depth.tobytes() == whole.depth.tobytes() and streamed.tot.tobytes() == whole.tot.tobytes()
    assert streamed.counts == whole.counts and list(tmp_path.iterdir()) == [path]  # no spill file left


def test_memory_does_not_grow_with_the_events(tmp_path):
    peaks, estimates = [], []
    for seconds in (1, 4):
        path = tmp_path / f"rec{seconds}.h5"
        write_file(path, seconds)
        with open_recording(path) as source:
            tracemalloc.start()
            result, _ = run_source(source, depth_network(SENSOR, **NET), chunk_events=50_000)
            peaks.append(tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
        estimates.append(len(result.depth))
    # the peak grows by the estimates kept (28 B each), not by the events (13 B each, ~3x as many)
    kept = (estimates[1] - estimates[0]) * 28
    assert peaks[1] - peaks[0] < kept + 2_000_000, (peaks, estimates)


def test_tofnet_run_streams_a_file_that_states_its_size_and_says_the_same(tmp_path, capsys):
    path = tmp_path / "rec.h5"
    write_file(path, 1)
    for name in ("streamed.npz", "read.npz"):
        args = ["run", str(path), "--out", str(tmp_path / name), "--velocity=-0.4,0.1,0.05", "--quiet"]
        if name == "read.npz":
            args += ["--monitor", "input.last_accepted@3,3"]  # monitors need the whole recording
        assert main(args) == 0
    assert "monitor" in capsys.readouterr().out
    a, b = np.load(tmp_path / "streamed.npz"), np.load(tmp_path / "read.npz")
    assert all(np.array_equal(a[k], b[k]) for k in ("t_us", "x", "y", "z", "step"))


def test_a_streamed_file_runs_in_the_bands_asked_for_and_gives_the_same_bytes(tmp_path):
    """A file read in chunks is a whole run: its packets are the backend's (2^19 events with workers),
    so the fused kernel takes its bands (a stream's first-packet rule keeps one band below 2^18)."""
    path = tmp_path / "rec.h5"
    assert write_file(path, 2) > 1 << 19
    results = {}
    for workers in (1, 2):
        with open_recording(path) as source:
            results[workers], _ = run_source(source, depth_network(SENSOR, **NET), backend_options={"workers": workers})
    assert results[2].summary()["workers"] == {"threads": 2, "bands": 2, "whole": [], "unit": "threads"}
    assert results[2].depth.tobytes() == results[1].depth.tobytes() and len(results[1].depth) > 10_000
    assert results[2].counts == results[1].counts


def test_a_run_that_asked_for_workers_and_kept_one_band_says_why(tmp_path, capsys):
    path = tmp_path / "rec.h5"
    write_file(path, 1)  # ~280,000 events: one chunk of 2^19
    with open_recording(path) as source:
        small = source.chunks(100_000)
        events = next(small)
    short = tmp_path / "short.h5"
    write_hdf5(short, [events], Recording(np.empty(0, EVENT_DTYPE), intrinsics=INTRINSICS, sensor_size=SENSOR))
    assert main(["run", str(short), "--workers", "2", "--out", str(tmp_path / "d.npz"), "--velocity=-0.4,0.1,0.05",
                 "--quiet"]) == 0
    assert ("workers        1 band of rows on 1 thread; one band: the first packet held 100,000 events; bands pay "
            "from 262,144 (docs/performance.md)") in capsys.readouterr().out


def test_a_streamed_files_reading_is_timed_apart_from_the_network(tmp_path, monkeypatch):
    """The file's decoding between packets is the input's time: the network's time (and the speed the
    summary derives from it) leaves it out, and the summary says it apart."""
    import time as clock

    path = tmp_path / "rec.h5"
    write_file(path, 1)
    slow_down = 0.05
    with open_recording(path) as source:
        chunks = source.chunks

        def slow(*args, **kwargs):
            for chunk in chunks(*args, **kwargs):
                clock.sleep(slow_down)  # a slow disk
                yield chunk
        source.chunks = slow
        result, _ = run_source(source, depth_network(SENSOR, **NET), chunk_events=50_000)
    pieces = -(-result.events_in // 50_000)
    assert pieces >= 5 and result.read_time >= pieces * slow_down and result.wall_time < pieces * slow_down
    assert result.summary()["read_time_s"] == result.read_time
