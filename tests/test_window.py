"""Time windows (--start/--duration/--until): parsed once, applied by the readers, the same for every format."""

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError, TofnetError
from tofnet.io import read_recording, write_ecd
from tofnet.io.source import open_recording
from tofnet.io.window import first_at_or_after
from tofnet.io.window import TimePoint, TimeWindow, parse_time, parse_window

from formats_helpers import pattern_recording
from optional import optional


@pytest.fixture(scope="module")
def recording():
    return pattern_recording()


def test_times_parse_exactly():
    assert parse_time("12.5s", "--start") == TimePoint(12_500_000)
    assert parse_time("500ms", "--start") == TimePoint(500_000)
    assert parse_time("0.0000015", "--start") == TimePoint(2)  # halves away from zero, from the decimal text
    assert parse_time("@1627000012.123457s", "--start") == TimePoint(1_627_000_012_123_457, True)
    assert parse_time("250us", "--start").us == 250
    for bad in ("soon", "12 parsecs", "@", "1e400", True):
        with pytest.raises(TofnetError, match="^--start: "):
            parse_time(bad, "--start")
    with pytest.raises(TofnetError, match="--duration: expected a time like 12.5s or 500ms, got '@1s'"):
        parse_window(duration="@1s")
    with pytest.raises(TofnetError, match="--duration and --until: give one of them"):
        parse_window(start="1s", duration="1s", until="3s")
    with pytest.raises(TofnetError, match="--duration: expected a positive duration"):
        parse_window(duration="0s")
    with pytest.raises(TofnetError, match="--until: 1 s is not after --start 2 s"):
        parse_window(start="2s", until="1s")
    assert parse_window() is None
    window = parse_window(start="@100s", duration="2s")
    assert window.resolve(5) == (100_000_000, 102_000_000)
    assert parse_window(start="1s", until="3s").resolve(10) == (1_000_010, 3_000_010)


def convert_recording(path, out):
    from tofnet.io.convert import convert

    with open_recording(path) as source:
        convert(source, out)


def _expected(events, start, stop):
    t = events["t"]
    return events[(t >= start) & (t < stop)]


def _formats(tmp_path, recording):
    """The same recording as an ECD folder, .npz, HDF5 (ms_to_idx) and AEDAT4 (when the extras are there)."""
    ecd = tmp_path / "ecd"
    write_ecd(ecd, recording.events, intrinsics=recording.intrinsics, times=recording.trajectory.times,
              positions=recording.trajectory.positions, quaternions=recording.trajectory.quaternions,
              sensor_size=recording.sensor_size)
    np.savetxt(ecd / "imu.txt", recording.imu, fmt="%.17g")
    paths = [ecd]
    for name, module in (("rec.npz", None), ("rec.h5", "h5py"), ("rec.aedat4", "faery")):
        if module is not None:
            optional(module)
        convert_recording(ecd, tmp_path / name)
        paths.append(tmp_path / name)
    return paths


def test_every_format_reads_the_same_window(tmp_path, recording):
    events = recording.events
    first = int(events["t"][0])
    start, stop = first + 100_000, first + 150_000
    want = _expected(events, start, stop)
    assert 0 < len(want) < len(events)
    for path in _formats(tmp_path, recording):
        whole = read_recording(path)
        for window in (parse_window(start="100ms", duration="50ms"), parse_window(start="0.1", until="150ms"),
                       parse_window(start=f"@{start}us", duration="50000us")):
            with open_recording(path, window=window) as source:
                read = source.read()
                assert source.window == (start, stop)
            assert np.array_equal(read.events, want), path
            assert any("time window 0.1 s .. 0.15 s from the first event" in n for n in read.notes)
            # Poses cut to those covering the window: the velocity inside it is unchanged.
            inside = np.linspace(start, stop - 1, 7) * 1e-6
            assert np.array_equal(read.trajectory.velocity_at(inside), whole.trajectory.velocity_at(inside))
            assert len(read.trajectory) < len(whole.trajectory)
            if path.suffix == ".aedat4":  # tofnet writes the IMU after the events: not reached
                assert read.imu is None
                continue
            assert read.imu[0, 0] * 1e6 <= start and read.imu[-1, 0] * 1e6 >= stop - 1
            assert np.all(np.diff(np.searchsorted(read.imu[:, 0] * 1e6, [start, stop])) > 0)


def test_windowed_ground_truth_depth_follows_the_events(tmp_path, recording):
    depth = np.linspace(1.0, 5.0, len(recording.events))
    write_ecd(tmp_path / "r", recording.events, intrinsics=None, sensor_size=recording.sensor_size, gt_depth=depth)
    read = read_recording(tmp_path / "r", window=parse_window(start="200ms"))
    keep = recording.events["t"] >= int(recording.events['t'][0]) + 200_000
    assert np.array_equal(read.events, recording.events[keep]) and np.array_equal(read.gt_depth, depth[keep])


def test_hdf5_reads_only_the_window_rows(tmp_path, recording, monkeypatch):
    h5py = optional("h5py")
    from tofnet.io.hdf5 import ColumnsSource

    write_ecd(tmp_path / "r", recording.events, intrinsics=None, sensor_size=recording.sensor_size)
    convert_recording(tmp_path / "r", tmp_path / "r.h5")
    asked = []
    rows = ColumnsSource._rows
    monkeypatch.setattr(ColumnsSource, "_rows", lambda self, lo, hi, n: asked.append((lo, hi)) or rows(self, lo, hi, n))
    window = parse_window(start="250ms", duration="10ms")
    with open_recording(tmp_path / "r.h5", window=window) as source:
        first = int(recording.events["t"][0])
        want = _expected(recording.events, first + 250_000, first + 260_000)
        assert source.n_events == len(want)  # from the index, before reading
        assert np.array_equal(source.read().events, want)
    lo = int(np.searchsorted(recording.events["t"], first + 250_000))
    assert asked == [(lo, lo + len(want))]
    # A wrong ms_to_idx cannot give wrong events: the search checks the times at its ends.
    with h5py.File(tmp_path / "r.h5", "r+") as f:
        f["ms_to_idx"][...] = 7
    assert np.array_equal(read_recording(tmp_path / "r.h5", window=window).events, want)


def test_binary_search_is_exact():
    t = np.sort(np.random.default_rng(1).integers(0, 10_000, 300_000))
    for value in (-5, 0, 17, 5000, 9999, 10_000, 20_000):
        want = int(np.searchsorted(t, value))
        assert first_at_or_after(lambda a, b: t[a:b], len(t), value) == want
        assert first_at_or_after(lambda a, b: t[a:b], len(t), value, bracket=(0, 3)) == want


def test_empty_and_past_the_end_windows_are_one_line(tmp_path, recording, capsys):
    write_ecd(tmp_path / "r", recording.events, intrinsics=None, sensor_size=recording.sensor_size)
    with pytest.raises(DataError, match=r"no events in the time window 5 s \.\. 6 s from the first event; "
                                        r"the recording ends 0\.29987 s after its first event"):
        read_recording(tmp_path / "r", window=parse_window(start="5s", duration="1s"))
    for args in (["info", str(tmp_path / "r"), "--start", "5s"],
                 ["run", str(tmp_path / "r"), "--start", "@1s", "--duration", "1s", "--out", str(tmp_path / "d.npz")],
                 ["info", str(tmp_path / "r"), "--start", "later"]):
        assert main(args) != 0
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and ("no events in the time window" in err or "--start" in err), err
    optional("h5py")
    convert_recording(tmp_path / "r", tmp_path / "r.h5")
    with pytest.raises(DataError, match="no events in the time window from 0.3 s after the first event to the end"):
        read_recording(tmp_path / "r.h5", window=TimeWindow(start=TimePoint(300_000)))


def test_run_of_a_window_equals_the_run_of_the_cut_recording(tmp_path, recording, capsys):
    from tofnet.io.depth import read_depth

    events = recording.events
    cut = _expected(events, int(events["t"][0]) + 50_000, int(events["t"][0]) + 200_000)
    for name, part in (("whole", events), ("cut", cut)):
        write_ecd(tmp_path / name, part, intrinsics=recording.intrinsics, times=recording.trajectory.times,
                  positions=recording.trajectory.positions, quaternions=recording.trajectory.quaternions,
                  sensor_size=recording.sensor_size)
    assert main(["run", str(tmp_path / "whole"), "--start", "50ms", "--until", "200ms", "--quiet",
                 "--out", str(tmp_path / "w.npz")]) == 0
    assert main(["run", str(tmp_path / "cut"), "--quiet", "--out", str(tmp_path / "c.npz")]) == 0
    out = capsys.readouterr().out
    windowed, _ = read_depth(tmp_path / "w.npz")
    whole_cut, _ = read_depth(tmp_path / "c.npz")
    assert len(windowed) > 0 and np.array_equal(windowed, whole_cut)
    assert main(["info", str(tmp_path / "whole"), "--start", "50ms", "--until", "200ms"]) == 0
    assert f"{len(cut):,}" in capsys.readouterr().out


def test_eval_and_export_window_the_estimates(tmp_path, capsys):
    from tofnet.io.depth import read_depth

    rec = tmp_path / "sim"
    assert main(["simulate", "slider", str(rec), "--duration", "0.3"]) == 0
    assert main(["run", str(rec), "--quiet", "--out", str(tmp_path / "d.npz")]) == 0
    capsys.readouterr()
    assert main(["eval", str(rec), str(tmp_path / "d.npz"), "--start", "100ms", "--duration", "100ms",
                 "--json", "-"]) == 0
    import json
    windowed = json.loads(capsys.readouterr().out)
    assert main(["eval", str(rec), str(tmp_path / "d.npz"), "--json", "-"]) == 0
    whole = json.loads(capsys.readouterr().out)
    assert 0 < windowed["estimates"] < whole["estimates"]
    assert main(["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path / "maps"), "--window", "50ms",
                 "--start", "100ms", "--duration", "100ms", "--no-png"]) == 0
    index = (tmp_path / "maps" / "index.csv").read_text().splitlines()
    assert len(index) == 1 + 2  # two 50 ms maps in the 100 ms window
    capsys.readouterr()
    assert main(["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path / "none"), "--window", "0ms"]) == 2
    assert "--window: expected a positive duration" in capsys.readouterr().err and not (tmp_path / "none").exists()
    depth, meta = read_depth(tmp_path / "d.npz")
    assert int(index[1].split(",")[4]) > 0


def test_eval_and_plot_of_a_windowed_run_read_its_window(tmp_path, capsys):
    """A run on a time window records it (absolute µs): eval and plot read those events, not the whole
    recording's (coverage over the run's events; a figure of the run's length), unless given another."""
    import json

    rec = tmp_path / "sim"
    assert main(["simulate", "slider", str(rec), "--duration", "0.3"]) == 0
    window = ["--start", "100ms", "--duration", "100ms"]
    assert main(["run", str(rec), "--quiet", "--out", str(tmp_path / "d.npz"), *window]) == 0
    capsys.readouterr()
    assert main(["eval", str(rec), str(tmp_path / "d.npz"), "--json", "-"]) == 0
    own = json.loads(capsys.readouterr().out)
    assert main(["eval", str(rec), str(tmp_path / "d.npz"), "--json", "-", *window]) == 0
    asked = json.loads(capsys.readouterr().out)
    assert own == asked and 0 < own["estimates"]
    assert main(["run", str(rec), "--quiet", "--out", str(tmp_path / "whole.npz")]) == 0
    capsys.readouterr()
    assert main(["eval", str(rec), str(tmp_path / "whole.npz"), "--json", "-"]) == 0
    assert json.loads(capsys.readouterr().out)["events_in"] > 2 * own["events_in"]
    from tofnet.eval.views import time_span_us
    from tofnet.cli.eval import load_inputs
    recording, depth, meta = load_inputs(str(rec), str(tmp_path / "d.npz"))
    start, end = time_span_us(recording.events, depth, meta["t0_us"])
    assert 0.1 <= (end - start) * 1e-6 < 0.11  # the figures' "whole run": the window's 100 ms


def test_a_depth_file_of_another_sensor_is_refused(tmp_path, capsys):
    rec, small = tmp_path / "sim", tmp_path / "small"
    assert main(["simulate", "slider", str(rec), "--duration", "0.1"]) == 0
    assert main(["simulate", "slider", str(small), "--duration", "0.1", "--sensor-size", "48x36"]) == 0
    assert main(["run", str(rec), "--quiet", "--out", str(tmp_path / "d.npz")]) == 0
    capsys.readouterr()
    for command in (["eval", str(small), str(tmp_path / "d.npz")],
                    ["plot", "depthmap", str(small), str(tmp_path / "d.npz"), "--out", str(tmp_path / "f.png")]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert "estimates lie outside" in err and "48x36 sensor: is it this recording's depth?" in err
    assert not (tmp_path / "f.png").exists()


def test_mvsec_rows_and_a_windowed_convert(tmp_path, recording):
    h5py = optional("h5py")
    events = recording.events
    rows = np.column_stack([events["x"], events["y"], events["t"] * 1e-6, np.where(events["p"] == 1, 1.0, -1.0)])
    with h5py.File(tmp_path / "seq_data.hdf5", "w") as f:
        f.create_dataset("davis/left/events", data=rows)
    whole = read_recording(tmp_path / "seq_data.hdf5")
    first = int(whole.events["t"][0])
    read = read_recording(tmp_path / "seq_data.hdf5", window=parse_window(start="120ms", until="180ms"))
    assert np.array_equal(read.events, _expected(whole.events, first + 120_000, first + 180_000))
    # tofnet convert writes the window, with the poses that cover it
    src = tmp_path / "ecd"
    write_ecd(src, events, intrinsics=recording.intrinsics, times=recording.trajectory.times,
              positions=recording.trajectory.positions, quaternions=recording.trajectory.quaternions,
              sensor_size=recording.sensor_size)
    assert main(["convert", str(src), str(tmp_path / "cut.h5"), "--start", "100ms", "--duration", "50ms"]) == 0
    cut = read_recording(tmp_path / "cut.h5")
    first = int(events["t"][0])
    assert np.array_equal(cut.events, _expected(events, first + 100_000, first + 150_000))
    assert cut.trajectory.times[0] * 1e6 <= first + 100_000 and len(cut.trajectory) < len(recording.trajectory)


def test_npy_windows_read_only_their_rows(tmp_path, recording):
    events = recording.events
    first = int(events["t"][0])
    rows = np.column_stack([events["x"], events["y"], (events["t"] - first) * 1e-6, events["p"]]).astype(np.float64)
    rows[5, 0] = -1  # a bad row outside the window: the whole file is refused, the window is not
    np.save(tmp_path / "plain.npy", rows)
    np.save(tmp_path / "plain_depth.npy", np.arange(len(rows), dtype=np.float64) + 1.0)
    with pytest.raises(DataError, match="pixel coordinates must be >= 0"):
        read_recording(tmp_path / "plain.npy", columns="x,y,t,p")
    read = read_recording(tmp_path / "plain.npy", columns="x,y,t,p", window=parse_window(start="100ms", duration="50ms"))
    keep = (events["t"] - first >= 100_000) & (events["t"] - first < 150_000)
    assert np.array_equal(read.events[["x", "y", "p"]], events[keep][["x", "y", "p"]])
    assert np.array_equal(read.events["t"], events["t"][keep] - first)
    assert np.array_equal(read.gt_depth, np.flatnonzero(keep) + 1.0)
    assert any("time window 0.1 s .. 0.15 s" in note for note in read.notes)
    with pytest.raises(DataError, match=r"no events in the time window from 1 s after the first event to the end; "
                                        r"the recording ends 0\.29987 s"):
        read_recording(tmp_path / "plain.npy", columns="x,y,t,p", window=parse_window(start="1s"))


def test_text_windows_parse_only_their_bytes(tmp_path, recording, monkeypatch):
    import tofnet.io.text_window as text_window
    from tofnet.io.events import write_events_txt

    events = recording.events
    write_events_txt(tmp_path / "events.txt", events)
    lines = (tmp_path / "events.txt").read_text().splitlines()
    # comments, blank lines and CRLF line ends, as the reader accepts them
    body = "# t x y p\r\n" + "\r\n".join(line if k % 97 else f"{line}\r\n\r\n# note" for k, line in enumerate(lines))
    (tmp_path / "events.txt").write_bytes(body.encode() + b"\r\n")
    whole = read_recording(tmp_path / "events.txt")
    assert np.array_equal(whole.events, events)
    monkeypatch.setattr(text_window, "REGION", 256)  # many probes on a small file
    first = int(events["t"][0])
    rng = np.random.default_rng(5)
    for start_ms, length_ms in [(0, 1), (0.0, 300), (299.8, 5)] + [tuple(rng.uniform(0, 300, 2)) for _ in range(12)]:
        start, stop = first + round(start_ms * 1000), first + round(start_ms * 1000) + round(length_ms * 1000)
        want = _expected(events, start, stop)
        window = TimeWindow(TimePoint(round(start_ms * 1000)), round(length_ms * 1000))
        if len(want) == 0:
            with pytest.raises(DataError, match="no events in the time window"):
                read_recording(tmp_path / "events.txt", window=window)
            continue
        assert np.array_equal(read_recording(tmp_path / "events.txt", window=window).events, want)
    # A bad line far from the window is not parsed; one inside it is reported with its line, as always.
    t3, _, y3, p3 = lines[3].split()
    bad = body.encode().replace(lines[3].encode(), f"{t3} x {y3} {p3}".encode(), 1)
    (tmp_path / "events.txt").write_bytes(bad)
    with pytest.raises(DataError, match=r"events.txt:7: column 'x': expected a number"):
        read_recording(tmp_path / "events.txt")
    late = parse_window(start="200ms", duration="50ms")
    assert np.array_equal(read_recording(tmp_path / "events.txt", window=late).events,
                          _expected(events, first + 200_000, first + 250_000))
    with pytest.raises(DataError, match=r"events.txt:7: column 'x': expected a number"):
        read_recording(tmp_path / "events.txt", window=parse_window(duration="1ms"))
    # An ECD folder without per-event true depth takes the same path.
    (tmp_path / "ecd").mkdir()
    (tmp_path / "ecd" / "events.txt").write_bytes(body.encode())
    read = read_recording(tmp_path / "ecd", window=late)
    assert np.array_equal(read.events, _expected(events, first + 200_000, first + 250_000))


def test_ros_bag_windows_stop_at_the_end(tmp_path, recording):
    optional("rosbags")
    from test_io_rosbag import write_bag

    write_bag(tmp_path / "r.bag", recording)
    first = int(recording.events["t"][0])
    read = read_recording(tmp_path / "r.bag", window=parse_window(start="120ms", duration="30ms"))
    assert np.array_equal(read.events, _expected(recording.events, first + 120_000, first + 150_000))
    inside = np.linspace(first + 120_000, first + 149_999, 5) * 1e-6
    whole = read_recording(tmp_path / "r.bag")
    assert np.allclose(read.trajectory.velocity_at(inside), whole.trajectory.velocity_at(inside), rtol=0, atol=0)


def test_a_text_window_survives_a_profiler_holding_its_frames(tmp_path, recording, monkeypatch):
    # Dask's profiler keeps the running task's frames; a finished frame keeps its views of the map,
    # which then cannot close. The read must still return its events (this failed a batch task).
    import sys

    import tofnet.io.text_window as text_window
    from tofnet.io.events import write_events_txt

    write_events_txt(tmp_path / "events.txt", recording.events)
    held = []
    search = text_window._window

    def sampled(buf, *args):
        held.append(sys._getframe())  # as a sampler would: this frame keeps ``buf``
        return search(buf, *args)

    monkeypatch.setattr(text_window, "_window", sampled)
    first = int(recording.events["t"][0])
    read = read_recording(tmp_path / "events.txt", window=parse_window(start="100ms", duration="50ms"))
    assert len(held) == 1
    assert np.array_equal(read.events, _expected(recording.events, first + 100_000, first + 150_000))


def test_a_window_without_events_says_it_as_asked_and_the_recordings_true_span(tmp_path, recording):
    """A window before the first event, or in a gap, of a file decoded from the start (RAW, DAT) stops
    decoding early: the message still gives the recording's true end, and ``@`` windows in ``@`` times."""
    from tofnet.io.window import absolute_text

    events = recording.events
    first, last = int(events["t"][0]), int(events["t"][-1])
    t = events["t"] - first
    gapped = events[(t < 100_000) | (t >= 200_000)]  # no events 100..200 ms
    write_ecd(tmp_path / "ecd", gapped, intrinsics=None, sensor_size=recording.sensor_size)
    paths = [tmp_path / "ecd"]
    for name, module in (("r.npz", None), ("r.h5", "h5py"), ("r.aedat4", "faery"), ("r.raw", "faery"),
                         ("r.dat", "faery")):
        if module is None or _installed(module):
            convert_recording(tmp_path / "ecd", tmp_path / name)
            paths.append(tmp_path / name)
    span = f"the recording's events span {absolute_text(first)} .. {absolute_text(last)} (0.29987 s)"
    for path in paths:
        for window, asked in ((parse_window(start=f"@{first - 2_000_000}us", duration="1s"),
                               f"{absolute_text(first - 2_000_000)} .. {absolute_text(first - 1_000_000)}"),
                              (parse_window(start="@0s", until=f"@{first}us"), f"@0.000000 s .. {absolute_text(first)}"),
                              (parse_window(start=f"@{first + 120_000}us", duration="50ms"),
                               f"{absolute_text(first + 120_000)} .. {absolute_text(first + 170_000)}")):
            with pytest.raises(DataError) as err:
                read_recording(path, window=window)
            assert str(err.value) == f"{path}: no events in the time window {asked}; {span}", path
        with pytest.raises(DataError) as err:  # relative times: said relative, with the true end
            read_recording(path, window=parse_window(start="120ms", duration="50ms"))
        assert str(err.value) == (f"{path}: no events in the time window 0.12 s .. 0.17 s from the first event; "
                                  "the recording ends 0.29987 s after its first event"), path


def _installed(module):
    import importlib.util
    return importlib.util.find_spec(module) is not None


def test_a_reader_that_decodes_from_the_start_finds_the_true_end_for_the_message(recording):
    """Decoding stops at the first packet past the window: the end the message gives is the file's, found by
    decoding the rest, not the last time decoded."""
    from tofnet.io.event_source import EventSource

    class Packets(EventSource):
        format = "test"

        def _packets(self, size_hint):
            for part in np.array_split(recording.events, 10):
                yield part

    from tofnet.io.window import absolute_text

    first, last = int(recording.events["t"][0]), int(recording.events["t"][-1])
    for window, asked in ((parse_window(start="@0s", duration="1s"), "@0.000000 s .. @1.000000 s"),
                          (parse_window(start="@0s", until=f"@{first}us"), f"@0.000000 s .. {absolute_text(first)}")):
        source = Packets("rec.test")
        source.set_window(window)
        with pytest.raises(DataError) as err:
            list(source.chunks())
        assert str(err.value) == (f"rec.test: no events in the time window {asked}; the recording's events span "
                                  f"{absolute_text(first)} .. {absolute_text(last)} (0.29987 s)")
