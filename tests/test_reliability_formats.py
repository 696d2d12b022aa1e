"""Issue 11's guarantees on issue 10's readers (docs/reliability.md): every path through
``read_recording``/``open_recording`` refuses non-regular files, checks sensor sizes,
intrinsics, IMU and event times in one place, reads numpy files without ``np.load``,
reports rounded times, and ``convert``/``export``/``info`` write like every other command."""

from __future__ import annotations

import json
import os
import socket

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError, TofnetError
from tofnet.events import EVENT_DTYPE
from tofnet.io import read_recording
from tofnet.io.source import EventSource, open_recording
from optional import optional


def _events(n: int = 5) -> np.ndarray:
    events = np.zeros(n, dtype=EVENT_DTYPE)
    events["t"] = 1000 * np.arange(1, n + 1)
    events["x"], events["y"], events["p"] = np.arange(n) % 7, 2, np.arange(n) % 2
    return events


def _one_line(err: pytest.ExceptionInfo) -> str:
    text = str(err.value)
    assert "\n" not in text and len(text) < 600
    return text


# ---------------------------------------------------------------- notes, numpy

def test_rounded_times_reach_the_recording_and_the_run_summary(tmp_path, capsys):
    path = tmp_path / "ev.txt"
    path.write_text("0.0010004 1 2 1\n0.0020005 2 2 0\n0.003 3 2 1\n")
    (tmp_path / "calib.txt").write_text("10 10 3.5 1.5\n")
    with open_recording(path) as source:
        notes = source.read().notes
    assert any("2 time(s) had digits below 1 µs" in note for note in notes)
    assert read_recording(path).events["t"].tolist() == [1000, 2001, 3000]  # half away from zero
    out = tmp_path / "d.npz"
    assert main(["run", str(path), "--velocity", "0.5,0,0", "--sensor-size", "16x8", "--out", str(out),
                 "--json", str(tmp_path / "s.json"), "--quiet"]) == 0
    assert "note           ev.txt: 2 time(s)" in capsys.readouterr().out
    assert any("2 time(s)" in note for note in json.loads((tmp_path / "s.json").read_text())["notes"])


def test_numpy_files_are_read_without_np_load(tmp_path, monkeypatch):
    events = _events()
    rows = np.column_stack([events["x"], events["y"], events["t"] * 1e-6, events["p"]])
    np.save(tmp_path / "rows.npy", rows)
    table = np.zeros(len(events), dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("polarity", "?")])
    for key in ("x", "y", "t"):
        table[key] = events[key]
    table["polarity"] = events["p"] == 1
    np.savez_compressed(tmp_path / "nimagenet.npz", event_data=table)
    np.savez(tmp_path / "on.npz", t=events["t"], x=events["x"], y=events["y"], on=events["p"] == 1,
             sensor_size=np.array([7, 3]), intrinsics=np.array([10.0, 10.0, 3.5, 1.5]))

    def refuse(*args, **kwargs):
        raise AssertionError("np.load must not be used on a user's file")
    monkeypatch.setattr(np, "load", refuse)
    assert np.array_equal(read_recording(tmp_path / "rows.npy", columns="x,y,t,p").events, events)
    assert np.array_equal(read_recording(tmp_path / "nimagenet.npz").events, events)
    recording = read_recording(tmp_path / "on.npz")
    assert np.array_equal(recording.events, events) and recording.sensor_size == (7, 3)
    with pytest.raises(DataError, match="--columns") as err:  # the hint survives the safe loader
        read_recording(tmp_path / "rows.npy")
    _one_line(err)


@pytest.mark.parametrize("key, value, message", [
    ("poses", np.zeros(8), r"\[poses\]: expected finite numbers of shape \(n, 8\)"),
    ("imu", np.array([[0.0, 1, 2, 3, 4, 5, np.nan]]), r"\[imu\]: expected finite numbers"),
    ("intrinsics", np.array([0.0, 10.0, 3.5, 1.5]), "focal lengths must be positive"),
    ("sensor_size", np.array([70000, 2]), "each side must be at most 65536"),
    ("distortion_model", np.array("x" * 500), r"\[distortion_model\]: expected 'radtan' or 'equidistant'"),
])
def test_npz_metadata_is_checked(tmp_path, key, value, message):
    events = _events()
    arrays = {k: events[k] for k in "txyp"}
    if key == "distortion_model":
        arrays["intrinsics"] = np.array([10.0, 10.0, 3.5, 1.5])
    np.savez(tmp_path / "rec.npz", **arrays, **{key: value})
    with pytest.raises(DataError, match=message) as err:
        read_recording(tmp_path / "rec.npz")
    assert "x" * 50 not in _one_line(err)


# ---------------------------------------------------------------- non-regular files, side files

@pytest.mark.parametrize("name", ["rec.h5", "rec.bag", "rec.aedat4", "events.txt", "rec.npz"])
def test_fifos_are_refused_unread_whatever_their_name(tmp_path, name):
    os.mkfifo(tmp_path / name)  # opening it for reading would block forever
    with pytest.raises(DataError, match="is a FIFO") as err:
        read_recording(tmp_path / name)
    _one_line(err)


def test_devices_sockets_and_folders_as_side_files_are_refused(tmp_path):
    with pytest.raises(DataError, match="is a character device"):
        read_recording("/dev/zero")
    server = socket.socket(socket.AF_UNIX)
    try:
        server.bind(str(tmp_path / "rec.bag"))
        with pytest.raises(DataError, match="is a socket"):
            read_recording(tmp_path / "rec.bag")
    finally:
        server.close()
    h5py = optional("h5py")
    with h5py.File(tmp_path / "rec.h5", "w") as out:
        for key in "txyp":
            out[f"events/{key}"] = _events()[key]
    (tmp_path / "calib.txt").mkdir()  # a folder where a side file is expected: not silently skipped
    with pytest.raises(DataError, match="calib.txt: is a folder"):
        read_recording(tmp_path / "rec.h5")


# ---------------------------------------------------------------- one check for every format

def _dsec(path, events, **extra):
    h5py = optional("h5py")
    with h5py.File(path, "w") as out:
        for key in "txyp":
            out[f"events/{key}"] = events[key]
        for key, value in extra.items():
            out[key] = value


@pytest.mark.parametrize("extra, message", [
    ({"calib/resolution": np.array([70000, 10])}, "sensor size: each side must be at most 65536"),
    ({"calib/resolution": np.array([5000, 5000])}, "at most 16,777,216 pixels"),
    ({"calib/intrinsics": np.array([np.nan, 1.0, 2.0, 3.0])}, "calib: fx is nan; expected a finite number of pixels"),
    ({"calib/intrinsics": np.array([-5.0, 1.0, 2.0, 3.0])}, "focal lengths must be positive"),
    ({"calib/intrinsics": np.array([1.0, 2.0, 3.0])}, "calib: expected 4 numbers fx fy cx cy, got 3"),
    ({"calib/resolution": np.int64(240)}, r"calib/resolution: expected two whole numbers \(width, height\)"),
    ({"calib/resolution": np.array([240.7, 180.2])}, r"calib/resolution: expected two whole numbers"),
    ({"imu/t": np.array([0.0, 0.5]), "imu/accel": np.zeros((3, 3)), "imu/gyro": np.zeros((2, 3))},
     "imu: t, accel and gyro hold 2, 3 and 2 samples; expected one count"),
    ({"poses/position": np.zeros((2, 3)), "poses/quaternion": np.tile([0.0, 0, 0, 1], (2, 1))},
     r"poses/t: missing \(poses needs t, position, quaternion\)"),
    ({"imu/t": np.array([1.0, 0.5]), "imu/accel": np.zeros((2, 3)), "imu/gyro": np.zeros((2, 3))},
     "IMU sample 1: time goes back"),
    ({"t_offset": np.int64(2**62)}, r"t_offset .* out of range"),
])
def test_what_an_hdf5_file_declares_is_checked(tmp_path, extra, message):
    _dsec(tmp_path / "rec.h5", _events(), **extra)
    with pytest.raises(DataError, match=message) as err:
        read_recording(tmp_path / "rec.h5")
    _one_line(err)


def test_hdf5_times_past_the_range_do_not_wrap(tmp_path):
    events = _events().astype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    events["t"][-1] = 2**63 + 5  # int64 would wrap to a negative, in-range-looking time
    _dsec(tmp_path / "rec.h5", events)
    with pytest.raises(DataError, match=r"event 5: t = 9223372036854775813 µs is out of range"):
        read_recording(tmp_path / "rec.h5")


def test_sensor_size_override_and_extent_are_checked_for_every_format(tmp_path):
    path = tmp_path / "ev.txt"
    path.write_text("0.001 1 2 1\n0.002 2 2 0\n")
    with pytest.raises(DataError, match="sensor size: each side must be at most 65536"):
        read_recording(path, sensor_size=(100_000, 10))
    with pytest.raises(DataError, match="sensor size: at most"):
        open_recording(path, sensor_size=(8192, 8192))

    class Wide(EventSource):  # a reader whose file does not say its size
        format = "test"

        def _packets(self, size_hint):
            events = _events(2)
            events["x"], events["y"] = [65535, 0], [0, 65535]
            yield events
    with pytest.raises(DataError, match="events' extent is not a usable one"):
        Wide(path).read()


class _Packets(EventSource):
    format = "test"

    def __init__(self, path, packets):
        super().__init__(path)
        self.packets = packets

    def _packets(self, size_hint):
        yield from self.packets


@pytest.mark.parametrize("dtype, t, message", [
    ("<u8", 2**63 + 1, r"event 3: time 9223372036854775809 µs is out of range"),
    ("<i8", -(2**61), r"event 3: time -2305843009213693952 µs is out of range"),
    ("<i8", 2**61, "out of range"),
])
def test_every_reader_s_events_are_range_checked_once_in_chunks(tmp_path, dtype, t, message):
    packet = np.zeros(3, dtype=[("t", dtype), ("x", "<u2"), ("y", "<u2"), ("on", "?")])
    packet["t"] = [1, 2, t] if t > 0 else [t, 1, 2]
    if t < 0:
        packet = packet[[1, 2, 0]]  # out of range before it could be out of order
    with pytest.raises(DataError, match=message) as err:
        list(_Packets(tmp_path / "x", [packet[:1], packet[1:]]).chunks(2))
    _one_line(err)


def test_coordinates_that_do_not_fit_uint16_are_refused_not_wrapped(tmp_path):
    packet = np.zeros(2, dtype=[("t", "<i8"), ("x", "<i4"), ("y", "<i4"), ("p", "u1")])
    packet["t"], packet["x"] = [1, 2], [3, 65536]
    with pytest.raises(DataError, match="event 2: x = 65536; expected a whole pixel coordinate"):
        list(_Packets(tmp_path / "x", [packet]).chunks())


def test_a_corrupt_ros_message_is_one_line(tmp_path):
    optional("rosbags")
    from rosbags.rosbag1 import Writer

    from tofnet.io.rosbag import typestore
    with Writer(tmp_path / "rec.bag") as writer:
        connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=typestore())
        writer.write(connection, 1000, b"\x01\x02\x03")  # not an EventArray
    with pytest.raises(DataError, match="rec.bag: not a readable ROS1 bag file") as err:
        read_recording(tmp_path / "rec.bag")
    _one_line(err)


def test_a_corrupt_side_topic_message_is_one_line(tmp_path):
    # found by benchmarks/fuzz.py (seed 2): rosbags raised SerdeError from a camera_info message
    optional("rosbags")
    from rosbags.rosbag1 import Writer

    from tofnet.io.rosbag import typestore
    store = typestore()
    with Writer(tmp_path / "rec.bag") as writer:
        info = writer.add_connection("/dvs/camera_info", "sensor_msgs/msg/CameraInfo", typestore=store)
        writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
        writer.write(info, 1000, bytes(12) + (158).to_bytes(4, "little") + bytes(40))  # a sequence longer than the message
    with pytest.raises(DataError, match="rec.bag: not a readable ROS1 bag file") as err:
        read_recording(tmp_path / "rec.bag")
    _one_line(err)


def test_aedat4_with_a_non_utf8_description_is_refused_before_faery_sees_it(tmp_path):
    # faery 0.7 aborts the process (a panic that cannot unwind) on such a header.
    optional("faery")
    from tofnet.fuzzing import seeds
    data = bytearray(seeds("aedat4")[0])
    at = data.index(b"<dv version")
    data[at + 1] = 0xE2  # starts a 3-byte UTF-8 sequence that does not go on
    (tmp_path / "rec.aedat4").write_bytes(bytes(data))
    with pytest.raises(DataError, match=r"header: the description is not UTF-8"):
        read_recording(tmp_path / "rec.aedat4")


# ---------------------------------------------------------------- convert, export, info write like the rest

def test_convert_checks_its_output_first_and_never_replaces_an_input(tmp_path, capsys):
    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "events.txt").write_text("0.001 1 2 1\n0.002 2 2 0\n")
    assert main(["convert", str(folder), str(folder), "--force", "--quiet"]) == 2
    assert "would overwrite the input" in capsys.readouterr().err
    assert main(["convert", str(folder / "events.txt"), str(tmp_path), "--force", "--quiet"]) == 2
    assert "holding the input" in capsys.readouterr().err
    (tmp_path / "out.npz").write_text("precious")
    assert main(["convert", str(tmp_path / "missing.txt"), str(tmp_path / "out.npz"), "--quiet"]) == 2
    assert "out.npz: output exists; pass --force" in capsys.readouterr().err  # before the input is read
    assert main(["convert", str(folder), str(tmp_path / "copy"), "--quiet"]) == 0
    assert main(["convert", str(folder), str(tmp_path / "copy"), "--quiet"]) == 2
    assert main(["convert", str(folder), str(tmp_path / "copy"), "--quiet", "--force"]) == 0
    assert (tmp_path / "out.npz").read_text() == "precious"
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".part")]


def test_a_failed_conversion_leaves_nothing_under_the_final_name(tmp_path):
    optional("h5py")
    from tofnet.io.convert import convert
    events = _events()
    late = events.copy()
    late["t"] -= 10_000  # the second packet goes back in time: found while writing
    with pytest.raises(DataError, match="time goes back"):
        convert(_Packets(tmp_path / "x", [events, late]), tmp_path / "out.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_export_and_info_refuse_to_clobber(tmp_path, capsys):
    path = tmp_path / "ev.txt"
    path.write_text("0.001 1 2 1\n0.002 2 2 0\n")
    (tmp_path / "calib.txt").write_text("10 10 3.5 1.5\n")
    (tmp_path / "facts.json").write_text("{}")
    assert main(["info", str(path), "--json", str(tmp_path / "facts.json"), "--quiet"]) == 2
    assert "--json exists; pass --force" in capsys.readouterr().err
    assert main(["info", str(path), "--json", str(tmp_path / "facts.json"), "--quiet", "--force"]) == 0
    assert json.loads((tmp_path / "facts.json").read_text())["events"] == 2
    depth = tmp_path / "d.npz"
    assert main(["run", str(path), "--velocity", "0.5,0,0", "--sensor-size", "16x8", "--out", str(depth),
                 "--quiet"]) == 0
    (tmp_path / "cloud.ply").write_text("precious")
    assert main(["export", str(depth), "--recording", str(path), "--ply", str(tmp_path / "cloud.ply")]) == 2
    assert "--ply exists; pass --force" in capsys.readouterr().err
    assert main(["export", str(depth), "--recording", str(path), "--ply", str(path)]) == 2
    assert "would overwrite the input" in capsys.readouterr().err
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "index.csv").write_text("old")
    assert main(["export", str(depth), "--recording", str(path), "--maps", str(tmp_path / "maps")]) == 2
    assert "'index.csv', which tofnet did not write" in capsys.readouterr().err
    assert (tmp_path / "cloud.ply").read_text() == "precious"


def test_run_checks_probe_files_before_reading(tmp_path, capsys):
    path = tmp_path / "ev.txt"
    path.write_text("0.001 1 2 1\n0.002 2 2 0\n")
    (tmp_path / "d.input.events.npz").write_text("precious")
    assert main(["run", str(tmp_path / "missing.txt"), "--out", str(tmp_path / "d.npz"),
                 "--probe", "input.events", "--quiet"]) == 2
    assert "d.input.events.npz: --probe 'input.events' exists" in capsys.readouterr().err
    for bad in ("../../x", "input", "input.events/../../y", "a.b.c"):  # it names a file beside --out
        with pytest.raises(SystemExit) as stop:  # argparse's one line
            main(["run", str(path), "--out", str(tmp_path / "d.npz"), "--probe", bad, "--quiet"])
        assert stop.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "expected PROCESS.PORT" in err[0], err


def test_errors_are_tofnet_errors_for_every_format(tmp_path):
    # A file that starts like a format and then is garbage: one line for each. (Not EVT:
    # any 16-bit words decode as EVT3 events, so garbage there is events, checked as such.)
    heads = {"rec.h5": b"\x89HDF\r\n\x1a\n", "rec.bag": b"#ROSBAG V2.0\n", "rec.aedat4": b"#!AER-DAT4.0\r\n",
             "rec.dat": b"% Version 2\n", "rec.es": b"Event Stream",
             "rec.npy": b"\x93NUMPY", "rec.npz": b"PK\x03\x04"}
    for name, head in heads.items():
        (tmp_path / name).write_bytes(head + bytes(range(256)) * 3)
        with pytest.raises(TofnetError) as err:
            read_recording(tmp_path / name)
        _one_line(err)


def test_nul_bytes_in_names_are_one_line(tmp_path, capsys):
    # Found by benchmarks/fuzz.py (seed 1): main's run passes --spec as a Path, which
    # reached os.open with the NUL byte.
    (tmp_path / "d.npz").write_text("old")
    words = [["run", str(tmp_path), "--spec", "\x00", "--out", str(tmp_path / "x.npz")],
             ["run", str(tmp_path), "--out", str(tmp_path / "a\x00.npz")],
             ["run", str(tmp_path), "--spec", "a\x00", "--out", str(tmp_path / "d.npz"), "--force"],
             ["info", str(tmp_path / "a\x00")], ["convert", str(tmp_path), str(tmp_path / "a\x00.npz")]]
    for argv in words:
        assert main(argv) == 2
        assert capsys.readouterr().err.count("\n") == 1
    from pathlib import Path

    from tofnet.io.spec import load_spec
    with pytest.raises(TofnetError, match="not a valid file name"):
        load_spec(Path("a\x00.yaml"))


def test_a_faery_panic_is_one_line(tmp_path):
    # A zeroed byte inside an AEDAT4 packet makes faery's flatbuffers code panic; pyo3
    # raises that as PanicException, a BaseException that `except Exception` misses.
    optional("faery")
    from tofnet.fuzzing import seeds
    data = bytearray(seeds("aedat4")[0])
    data[1138] = 0
    (tmp_path / "rec.aedat4").write_bytes(bytes(data))
    with pytest.raises(DataError) as err:
        read_recording(tmp_path / "rec.aedat4")
    _one_line(err)


def test_a_long_process_type_in_a_spec_is_cut(tmp_path):
    from tofnet.errors import SpecError
    from tofnet.io.spec import load_spec
    text = "processes:\n  a: {type: Depth" + "9" * 5000 + "}\nconnections: []\n"
    with pytest.raises(SpecError, match=r"unknown process type 'Depth9+\.\.\.;") as err:
        load_spec(text)
    _one_line(err)
