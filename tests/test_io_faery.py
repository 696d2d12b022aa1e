"""AEDAT4, Prophesee RAW (EVT2, EVT2.1, EVT3), DAT and Event Stream, with fixtures written by faery itself."""

import sys

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.io import read_recording
from tofnet.io.source import open_recording
from optional import optional

faery = optional("faery")

from formats_helpers import SENSOR, faery_events, pattern_recording  # noqa: E402


@pytest.fixture(scope="module")
def recording():
    return pattern_recording()


def _write(path, events, **kwargs):
    faery.events_stream_from_array(faery_events(events), dimensions=SENSOR).to_file(path, **kwargs)


@pytest.mark.parametrize("name, kwargs, detail", [
    ("rec.aedat4", {}, "events track 0"),
    ("rec.raw", {"version": "evt3"}, "EVT3"),
    ("rec.raw", {"version": "evt2"}, "EVT2"),
    ("rec.dat", {}, "DAT2, cd"),
])
def test_files_written_by_faery_read_back_exactly(tmp_path, recording, name, kwargs, detail):
    path = tmp_path / name
    _write(path, recording.events, **kwargs)
    source = open_recording(path)
    assert source.detail == detail
    assert source.sensor_size == SENSOR
    assert source.n_events in (None, len(recording.events))
    read = read_recording(path)
    assert np.array_equal(read.events, recording.events)


def test_event_stream_reads_back_relative_to_its_first_event(tmp_path, recording):
    # Event Stream keeps no absolute start time: times come back from the first event on.
    path = tmp_path / "rec.es"
    _write(path, recording.events)
    events = read_recording(path).events
    expected = recording.events.copy()
    expected["t"] -= expected["t"][0]
    assert np.array_equal(events, expected)


@pytest.mark.parametrize("cut", [1, 2, 3, 4, 5, 6])
def test_an_event_stream_cut_inside_an_event_is_read_to_its_last_whole_event_and_noted(tmp_path, recording, cut):
    path = tmp_path / "rec.es"
    _write(path, recording.events)
    whole = path.read_bytes()
    (tmp_path / "cut.es").write_bytes(whole[:len(whole) - cut])
    read = read_recording(tmp_path / "cut.es")
    lost = 1 if cut <= 5 else 2  # 5 bytes per event (no overflow before the last two at this rate)
    assert np.array_equal(read.events, read_recording(path).events[:-lost])
    partial = [note for note in read.notes if "partial" in note]
    if cut == 5:  # the cut falls between two events: nothing to say
        assert partial == []
    else:
        bytes_left = 5 - cut % 5
        assert partial == [f"the file ends with {bytes_left} byte{'s' if bytes_left > 1 else ''} of a partial 5-byte "
                           "event (not read): truncated?"]
    assert not any("partial" in note for note in read_recording(path).notes)


@pytest.mark.parametrize("chunk", [1, 997, 10_000, 10**7])
def test_chunks_are_time_ordered_copies_of_the_whole(tmp_path, recording, chunk):
    path = tmp_path / "rec.raw"
    _write(path, recording.events, version="evt3")
    with open_recording(path) as source:
        chunks = list(source.chunks(chunk)) if chunk != 1 else list(source.chunks(1))[:50]
    assert all(len(c) == chunk for c in chunks[:-1])
    whole = np.concatenate(chunks)
    assert np.array_equal(whole, recording.events[:len(whole)])
    if chunk > 1:
        assert len(whole) == len(recording.events)


def test_progress_hook_reports_events_read(tmp_path, recording):
    path = tmp_path / "rec.dat"
    _write(path, recording.events)
    calls = []
    read_recording(path, progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (len(recording.events), len(recording.events))  # DAT: total from the file size
    assert [done for done, _ in calls] == sorted(done for done, _ in calls)


def test_aedat4_with_imu_and_calibration_side_files(tmp_path, recording):
    from tofnet.io.aedat import write_aedat4
    from tofnet.io.calibration import write_calibration

    path = tmp_path / "rec.aedat4"
    write_aedat4(path, [recording.events[:1000], recording.events[1000:]], recording)
    write_calibration(tmp_path / "calib.txt", recording.intrinsics)
    source = open_recording(path)
    assert source.n_events == len(recording.events)
    assert any("imus" in name for name in source.streams)
    read = source.read()
    assert np.array_equal(read.events, recording.events)
    assert read.imu.shape == recording.imu.shape
    # stored as float32 g and °/s by the format
    assert np.allclose(read.imu, recording.imu, rtol=1e-6, atol=1e-6)
    assert read.intrinsics == recording.intrinsics
    assert any("calib.txt" in note for note in read.notes)


def _aedat4_with_triggers(path, events):
    """An AEDAT4 file as a DAVIS writes one: events, an IMU track (without samples here) and 5 triggers."""
    from faery.extension import aedat
    from tofnet.io.aedat import _track_node
    from tofnet.io.faery_shared import faery_packet

    tracks = [_track_node(0, "EVTS", "events", {"sizeX": ("int", SENSOR[0]), "sizeY": ("int", SENSOR[1])}),
              _track_node(1, "IMUS", "imu", {}), _track_node(2, "TRIG", "triggers", {})]
    description = [aedat.DescriptionNode(name="outInfo", path="/mainloop/Recorder/outInfo/", attributes={},
                                         nodes=tracks)]
    triggers = np.zeros(5, dtype=[("t", "<u8"), ("source", "u1")])
    triggers["t"] = events["t"][:5]
    with aedat.Encoder(path=path, description=description, compression=aedat.LZ4_DEFAULT) as encoder:
        encoder.write(0, faery_packet(events))
        encoder.write(2, triggers)


def test_convert_says_which_aedat4_streams_it_does_not_write(tmp_path, recording, capsys):
    from tofnet.cli import main

    _aedat4_with_triggers(tmp_path / "davis.aedat4", recording.events)
    source = open_recording(tmp_path / "davis.aedat4")
    assert source.streams == {"imus (track 1)": "0 samples (read as the IMU)", "triggers (track 2)": "5 triggers"}
    assert np.array_equal(source.read().events, recording.events) and source.imu is None
    unwritten = ("not written: triggers (track 2), 5 triggers (tofnet reads only the events, camera, poses and IMU "
                 "of davis.aedat4)")
    for out in ("out.aedat4", "out", "out.npz"):
        assert main(["convert", str(tmp_path / "davis.aedat4"), str(tmp_path / out), "--quiet"]) == 0
        assert unwritten in capsys.readouterr().out.splitlines(), out
    # what tofnet wrote holds the events only: no IMU track, so nothing for info to contradict
    written = open_recording(tmp_path / "out.aedat4")
    assert written.streams == {} and written.unread == [] and written.read().imu is None
    assert np.array_equal(read_recording(tmp_path / "out.aedat4").events, recording.events)
    assert main(["info", str(tmp_path / "out.aedat4"), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "imu            none" in printed and "other stream" not in printed, printed


def test_aedat4_declares_an_imu_track_only_with_an_imu(tmp_path, recording):
    from tofnet.io.aedat import write_aedat4
    from tofnet.io.recording import Recording

    bare = Recording(events=recording.events, sensor_size=SENSOR)
    write_aedat4(tmp_path / "bare.aedat4", [recording.events], bare)
    source = open_recording(tmp_path / "bare.aedat4")
    assert source.streams == {} and source.metadata().imu is None and source.read().imu is None
    write_aedat4(tmp_path / "imu.aedat4", [recording.events], recording)
    source = open_recording(tmp_path / "imu.aedat4")
    assert source.streams == {"imus (track 1)": f"{len(recording.imu)} samples (read as the IMU)"}
    assert np.allclose(source.read().imu, recording.imu, rtol=1e-6, atol=1e-6)
    # an AEDAT4 source's IMU comes with its events: declared before they are read, written after them
    with open_recording(tmp_path / "imu.aedat4") as again:
        write_aedat4(tmp_path / "copy.aedat4", again.chunks(), again)
    assert np.allclose(read_recording(tmp_path / "copy.aedat4").imu, recording.imu, rtol=1e-6, atol=1e-6)
    with open_recording(tmp_path / "bare.aedat4") as again:
        write_aedat4(tmp_path / "copy_bare.aedat4", again.chunks(), again)
    assert open_recording(tmp_path / "copy_bare.aedat4").streams == {}


def test_aedat4_metadata_holds_the_imu_read_once_up_to_the_window(tmp_path, recording, monkeypatch):
    """The IMU comes among the packets: metadata() decodes the file for it once, stopping after the window."""
    from tofnet.io import aedat
    from tofnet.io.window import parse_window

    path = tmp_path / "rec.aedat4"
    aedat.write_aedat4(path, [recording.events], recording)
    whole = open_recording(path).metadata().imu
    assert np.allclose(whole, recording.imu, rtol=1e-6, atol=1e-6)
    calls = []
    source_class = type(open_recording(path))
    real = source_class._read_imu
    monkeypatch.setattr(source_class, "_read_imu", lambda self: (calls.append(1), real(self)))
    span = (recording.events["t"][-1] - recording.events["t"][0]) * 1e-6
    windowed = open_recording(path, window=parse_window(duration=span / 4))
    first, second = windowed.metadata().imu, windowed.metadata().imu
    assert calls == [1] and first is second
    end_s = (windowed.window[1]) * 1e-6
    assert first[0, 0] <= windowed.window[0] * 1e-6 and first[-1, 0] >= end_s and len(first) < len(whole)
    assert open_recording(path).metadata(imu=False).imu is None and calls == [1]


def test_evt_header_without_size_gives_unknown_sensor_then_extent(tmp_path, recording):
    path = tmp_path / "rec.raw"
    _write(path, recording.events, version="evt2")
    from formats_helpers import strip_geometry
    strip_geometry(path, tmp_path / "bare.raw")
    source = open_recording(tmp_path / "bare.raw")
    assert source.sensor_size is None
    read = source.read()
    assert np.array_equal(read.events, recording.events)
    extent = (int(recording.events["x"].max()) + 1, int(recording.events["y"].max()) + 1)
    assert read.sensor_size == extent and any("extent" in note for note in read.notes)
    assert read_recording(tmp_path / "bare.raw", sensor_size=SENSOR).sensor_size == SENSOR
    from tofnet.io.convert import convert
    extent_text = f"sensor size {extent[0]}x{extent[1]} from the events' extent (the input does not say)"
    for name, said in (("out.npz", extent_text), ("out.dat", extent_text), ("ecd", extent_text)):
        assert said in convert(open_recording(tmp_path / "bare.raw"), tmp_path / name)  # said, whatever the output
    import importlib.util
    if importlib.util.find_spec("h5py"):  # the hdf5 extra
        assert "not written: sensor size (the input does not say; read back, the events' extent gives it)" in \
            convert(open_recording(tmp_path / "bare.raw"), tmp_path / "out.h5")


def test_missing_extra_is_one_line_naming_it(tmp_path, recording, monkeypatch):
    path = tmp_path / "rec.aedat4"
    _write(path, recording.events)
    monkeypatch.setitem(sys.modules, "faery", None)
    with pytest.raises(DataError) as caught:
        read_recording(path)
    message = str(caught.value)
    assert "\n" not in message and "rec.aedat4" in message and "pip install \"tofnet[formats]\"" in message


def test_evt_decoder_keeps_times_monotonic(tmp_path, recording):
    # An EVT3 event stamped before its predecessor gets the predecessor's stamp (tofnet's EVT3
    # decoder keeps time order so, and counts it in a note: docs/formats.md, "EVT3 timing").
    events = recording.events.copy()
    events["t"][500] = events["t"][499] - 10
    path = tmp_path / "rec.raw"
    _write(path, events, version="evt3", enforce_monotonic_timestamps=False)
    recording = read_recording(path)
    read = recording.events
    assert read["t"][500] == events["t"][499]
    assert any(note.startswith("1 EVT3 events") for note in recording.notes)
    assert np.array_equal(np.delete(read, 500), np.delete(events, 500))


def test_an_aedat4_file_cut_short_is_read_up_to_its_last_whole_packet_with_a_note(tmp_path, recording):
    from tofnet.io.aedat import TRUNCATED, write_aedat4
    path = tmp_path / "rec.aedat4"
    packets = [recording.events[i:i + 500] for i in range(0, len(recording.events), 500)]
    write_aedat4(path, packets, recording)
    data = path.read_bytes()
    cut = tmp_path / "cut.aedat4"
    cut.write_bytes(data[:len(data) // 2])  # an interrupted recording: no index table, a packet cut in two
    read = read_recording(cut)
    assert 0 < len(read.events) < len(recording.events) and len(read.events) % 500 == 0
    assert np.array_equal(read.events, recording.events[:len(read.events)])
    assert TRUNCATED in read.notes
    (tmp_path / "bad.aedat4").write_bytes(data[:len(data) // 2] + b"\xff" * 64 + data[len(data) // 2 + 64:])
    with pytest.raises(DataError):  # garbage inside the file is not a cut: refused
        read_recording(tmp_path / "bad.aedat4")


def test_aedat4_metadata_holds_the_whole_imu_after_the_first_events_were_looked_at(tmp_path, recording):
    """Opening looks at the first packet's times (the plausibility notes): the IMU samples decoded before it are
    not taken for the recording's IMU (a streaming run builds its network from the metadata's)."""
    from faery.extension import aedat

    from tofnet.io import aedat as tofnet_aedat
    path = tmp_path / "imu_first.aedat4"
    tracks = [tofnet_aedat._track_node(0, "EVTS", "events", {"sizeX": ("int", SENSOR[0]), "sizeY": ("int", SENSOR[1])}),
              tofnet_aedat._track_node(1, "IMUS", "imu", {})]
    description = [aedat.DescriptionNode(name="outInfo", path="/mainloop/Recorder/outInfo/", attributes={},
                                         nodes=tracks)]
    events, imu = recording.events, recording.imu
    with aedat.Encoder(path=path, description=description, compression=aedat.LZ4_DEFAULT) as encoder:
        for packet in tofnet_aedat._imu_packets(imu[:5]):  # some IMU, then events, then the rest of the IMU
            encoder.write(1, packet)
        encoder.write(0, tofnet_aedat.faery_packet(events[:1000]))
        for packet in tofnet_aedat._imu_packets(imu[5:]):
            encoder.write(1, packet)
        encoder.write(0, tofnet_aedat.faery_packet(events[1000:]))
    source = open_recording(path)
    assert source.metadata().imu.shape == imu.shape


def test_an_indexed_aedat4_file_with_a_corrupt_packet_is_refused(tmp_path, recording):
    """A file with an index table was closed properly: an end of data inside it is corruption, not a cut."""
    import struct

    from tofnet.io.aedat import write_aedat4
    path = tmp_path / "ten.aedat4"
    write_aedat4(path, np.array_split(recording.events, 10), recording)
    data = bytearray(path.read_bytes())
    at = len(b"#!AER-DAT4.0\r\n")
    at += 4 + struct.unpack_from("<i", data, at)[0]  # past the header
    for _ in range(3):  # past three packets (stream id, size, data)
        at += 8 + struct.unpack_from("<ii", data, at)[1]
    struct.pack_into("<i", data, at + 4, 0x7FFFFF00)  # the fourth's size: past the end of the file
    (tmp_path / "corrupt.aedat4").write_bytes(bytes(data))
    with pytest.raises(DataError, match="cannot decode"):
        read_recording(tmp_path / "corrupt.aedat4")
