"""event_camera_msgs/EventPacket (evt3, mono) in ROS1 and ROS 2 bags, against decoders written here from
the specifications, on bags in the layout of the event_camera_py project's samples
(``/event_camera/events``, one packet every few hundred words), written with rosbags.

EVT3 (Prophesee EVT 3.0): 16-bit words, type in the top 4 bits; TIME_HIGH / TIME_LOW the
upper / lower 12 bits of a 24-bit µs counter, which wraps (a TIME_HIGH going back is
2^24 µs more); the decoder state runs on from packet to packet; nothing before the first
TIME_HIGH followed by a TIME_LOW has a time (event_camera_codecs). ``time_base`` is not
used for evt3. mono (event_camera_codecs): little-endian uint64, bits 0-31 dt (ns), 32-47
x, 48-62 y, 63 polarity; time = time_base + dt ns.
"""

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.events import EVENT_DTYPE
from tofnet.io import read_recording
from tofnet.io.source import open_recording
from optional import optional

optional("rosbags")

from formats_helpers import SENSOR, T0_US, pattern_recording  # noqa: E402

TOPIC = "/event_camera/events"
#: Sensor clock of the first event: 30 ms before the 24-bit counter wraps.
SENSOR_START = (1 << 24) - 30_000
EVENTS = pattern_recording(duration_us=60_000).events
SENSOR_EVENTS = EVENTS.copy()
SENSOR_EVENTS["t"] = EVENTS["t"] - T0_US + SENSOR_START


# ------------------------------------------------------------------ written from the specifications

def evt3_words(events: np.ndarray) -> np.ndarray:
    """EVT3 words for ``events`` (t = sensor µs): TIME_HIGH/TIME_LOW when they change, ADDR_Y, then
    a VECT_BASE_X + VECT_8 for two or more same-time, same-row, same-polarity events within 8
    pixels, else EVT_ADDR_X per event. Starts with an ADDR_Y + ADDR_X that has no time yet."""
    words = [0x0000 | 5, 0x2000 | 7]
    high = low = y = None
    i = 0
    while i < len(events):
        t, ey = int(events["t"][i]), int(events["y"][i])
        if (t >> 12) & 0xFFF != high:
            high = (t >> 12) & 0xFFF
            words.append(0x8000 | high)
            low = None
        if t & 0xFFF != low:
            low = t & 0xFFF
            words.append(0x6000 | low)
        if ey != y:
            y = ey
            words.append(0x0000 | y)
        j = i
        while (j + 1 < len(events) and events["t"][j + 1] == t and events["y"][j + 1] == ey
               and events["p"][j + 1] == events["p"][i] and 0 < events["x"][j + 1] - events["x"][i] < 8
               and events["x"][j + 1] > events["x"][j]):
            j += 1
        pol = int(events["p"][i])
        if j > i:
            base = int(events["x"][i])
            bits = sum(1 << int(events["x"][k] - base) for k in range(i, j + 1))
            words += [0x3000 | (pol << 11) | base, 0x5000 | bits]
        else:
            words.append(0x2000 | (pol << 11) | int(events["x"][i]))
        i = j + 1
    return np.asarray(words, dtype="<u2")


def spec_evt3(packets: list[np.ndarray]) -> np.ndarray:
    """Decode EVT3 packets in order, one state for the topic (Prophesee's EVT 3.0 page)."""
    out = []
    high = low = loops = y = base = pol = 0
    timed = False
    for words in packets:
        seen_high = False
        for word in (int(w) for w in words):
            kind, value = word >> 12, word & 0xFFF
            if not timed:  # only time words count until a TIME_HIGH is followed by a TIME_LOW
                if kind == 0x8:
                    loops, high, seen_high = loops + (value < high), value, True
                elif kind == 0x6:
                    low, timed = value, seen_high
                continue
            now = (loops << 24) | (high << 12) | low
            if kind == 0x8:
                loops += value < high
                high = value
            elif kind == 0x6:
                low = value
            elif kind == 0x0:
                y = value & 0x7FF
            elif kind == 0x2:
                out.append((now, value & 0x7FF, y, value >> 11))
            elif kind == 0x3:
                base, pol = value & 0x7FF, value >> 11
            elif kind in (0x4, 0x5):
                size = 12 if kind == 0x4 else 8
                out += [(now, base + b, y, pol) for b in range(size) if value >> b & 1]
                base += size
    return np.array(out, dtype=EVENT_DTYPE)


def mono_bytes(events: np.ndarray, ns: np.ndarray, time_base: int) -> np.ndarray:
    packed = ((ns - time_base).astype(np.uint64) | events["x"].astype(np.uint64) << np.uint64(32)
              | events["y"].astype(np.uint64) << np.uint64(48) | events["p"].astype(np.uint64) << np.uint64(63))
    return packed.astype("<u8").view(np.uint8)


def spec_mono(packets: list[tuple[int, np.ndarray]]) -> np.ndarray:
    out = []
    for time_base, data in packets:
        for i in range(0, len(data), 8):
            word = int.from_bytes(bytes(data[i:i + 8]), "little")
            ns = time_base + (word & 0xFFFFFFFF)
            out.append(((ns + 500) // 1000, word >> 32 & 0xFFFF, word >> 48 & 0x7FFF, word >> 63))
    return np.array(out, dtype=EVENT_DTYPE)


# ------------------------------------------------------------------ bags

def evt3_packets(words_per_packet=300):
    words = evt3_words(SENSOR_EVENTS)
    return [words[i:i + words_per_packet] for i in range(0, len(words), words_per_packet)]


def mono_ns():
    """Event times in ns, 0, 250 or 500 ns past the µs (a half rounds up), kept in order."""
    return np.maximum.accumulate(EVENTS["t"].astype(np.int64) * 1000 + (np.arange(len(EVENTS)) % 3) * 250)


def mono_packets(per_packet=700):
    ns = mono_ns()
    packets = []
    for start in range(0, len(EVENTS), per_packet):
        part = slice(start, start + per_packet)
        time_base = int(ns[part].min()) - 17
        packets.append((time_base, mono_bytes(EVENTS[part], ns[part], time_base)))
    return packets


def write_packets(path, ros, encoding, packets, *, store=None, topic=TOPIC, storage="sqlite3"):
    """EventPacket messages on ``topic``: ``packets`` are (time_base, bytes); ROS1 .bag or ROS 2 folder."""
    from tofnet.io.ros_types import typestore

    version = 1 if ros == 1 else 2
    store = store or typestore(version)
    types = store.types
    if ros == 1:
        from rosbags.rosbag1 import Writer
        writer = Writer(path)
        serialize = store.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer
        writer = Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP)
        serialize = store.serialize_cdr
    with writer:
        connection = writer.add_connection(topic, "event_camera_msgs/msg/EventPacket", typestore=store)
        for seq, (time_base, data) in enumerate(packets):
            stamp_ns = T0_US * 1000 + seq * 1_000_000
            fields = dict(stamp=types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                          frame_id="event_camera")
            if ros == 1:
                fields["seq"] = seq
            message = types["event_camera_msgs/msg/EventPacket"](
                header=types["std_msgs/msg/Header"](**fields), height=SENSOR[1], width=SENSOR[0], seq=seq,
                time_base=time_base, encoding=encoding, is_bigendian=False, events=np.asarray(data, np.uint8).view(np.uint8))
            writer.write(connection, stamp_ns, serialize(message, "event_camera_msgs/msg/EventPacket"))


BAGS = [(1, "sqlite3", "events.bag"), (2, "sqlite3", "events_db3"), (2, "mcap", "events_mcap")]


@pytest.mark.parametrize("ros, storage, name", BAGS)
def test_evt3_packets_decode_exactly_across_the_time_wrap(tmp_path, ros, storage, name):
    packets = evt3_packets()
    wrap = next(i for i, words in enumerate(packets) if np.any(words[words >> 12 == 0x8] == 0x8000))
    assert wrap > 0  # the 24-bit counter wraps in a later packet than the first events
    expected = spec_evt3(packets)
    assert np.array_equal(expected, SENSOR_EVENTS)  # the test's own encoder and decoder agree
    write_packets(tmp_path / name, ros, "evt3", [(0, words.view(np.uint8)) for words in packets], storage=storage)
    source = open_recording(tmp_path / name)
    assert source.topics == {"events": TOPIC} and source.sensor_size == SENSOR
    read = source.read()
    assert np.array_equal(read.events, expected)
    assert read.events["t"][-1] > 1 << 24
    assert any(note.startswith("1 EVT3 events before the topic's first time stamp") for note in read.notes)


@pytest.mark.parametrize("ros, storage, name", BAGS)
def test_mono_packets_decode_exactly(tmp_path, ros, storage, name):
    packets = mono_packets()
    expected = spec_mono(packets)
    ns = mono_ns()
    assert np.array_equal(expected["t"], (ns + 500) // 1000) and np.count_nonzero(ns % 1000 == 500) > 100
    assert np.array_equal(expected[["x", "y", "p"]], EVENTS[["x", "y", "p"]])
    write_packets(tmp_path / name, ros, "mono", packets, storage=storage)
    assert np.array_equal(read_recording(tmp_path / name).events, expected)


def test_window_and_topic_choice_on_event_packets(tmp_path):
    from tofnet.io.window import parse_window

    write_packets(tmp_path / "two.bag", 1, "mono", mono_packets())
    path = tmp_path / "two.bag"
    whole = read_recording(path).events
    part = read_recording(path, window=parse_window("5ms", "10ms", None)).events
    start = int(whole["t"][0]) + 5_000
    assert np.array_equal(part, whole[(whole["t"] >= start) & (whole["t"] < start + 10_000)])
    assert open_recording(path, topics={"events": TOPIC}).topics["events"] == TOPIC


def _lookalike_store(version):
    """EventPacket with ``int64 time_base``: the same 8 bytes as uint64, another type."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from tofnet.io.ros_types import EVENT_CAMERA_MSGS

    store = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.LATEST)
    text = EVENT_CAMERA_MSGS["event_camera_msgs/msg/EventPacket"].replace("uint64 time_base", "int64 time_base")
    store.register(get_types_from_msg(text, "event_camera_msgs/msg/EventPacket"))
    return store


@pytest.mark.parametrize("ros, storage, name", BAGS)
def test_a_lookalike_event_packet_is_refused_in_one_line(tmp_path, capsys, ros, storage, name):
    write_packets(tmp_path / name, ros, "mono", mono_packets()[:2], store=_lookalike_store(ros), storage=storage)
    assert main(["info", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "non-standard message definition" in err[0] and TOPIC in err[0], err


def test_an_encoding_not_decoded_is_one_line(tmp_path):
    write_packets(tmp_path / "cmp.bag", 1, "libcaer_cmp", [(0, np.zeros(16, np.uint8))])
    with pytest.raises(DataError) as caught:
        read_recording(tmp_path / "cmp.bag")
    message = str(caught.value)
    assert "\n" not in message and "'libcaer_cmp' is not decoded" in message and "message 0" in message


def test_evt3_bytes_of_odd_length_are_refused(tmp_path):
    words = evt3_packets()[0]
    write_packets(tmp_path / "odd.bag", 1, "evt3", [(0, words.view(np.uint8)[:-1])])
    with pytest.raises(DataError, match="bytes of evt3 events"):
        read_recording(tmp_path / "odd.bag")


def _humble(folder, version, storage_identifier):
    """Rewrite a bag folder as event_camera_py's samples are: older metadata.yaml (no type hash), and
    for sqlite3 a database without message definitions (ROS 2 Humble)."""
    import sqlite3

    for db3 in folder.glob("*.db3"):
        connection = sqlite3.connect(db3)
        connection.execute("DELETE FROM message_definitions")
        connection.execute("UPDATE topics SET type_description_hash=''")
        connection.commit()
        connection.close()
    storage = next(p for p in folder.iterdir() if p.suffix in (".db3", ".mcap"))
    (folder / "metadata.yaml").write_text(f"""rosbag2_bagfile_information:
  version: {version}
  storage_identifier: "{storage_identifier}"
  relative_file_paths:
    - {storage.name}
  duration:
    nanoseconds: 1795796872
  starting_time:
    nanoseconds_since_epoch: 1675954746294044105
  message_count: 1
  topics_with_message_count:
    - topic_metadata:
        name: {TOPIC}
        type: event_camera_msgs/msg/EventPacket
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: 1
  compression_format: ""
  compression_mode: ""
""")


def test_the_metadata_of_event_camera_py_samples(tmp_path):
    """test_events_ros2_1: version 4, sqlite3 of Humble (no definitions: noted); test_events_2: version 5 with
    an empty storage_identifier and an MCAP file (read as its content says)."""
    packets = [(0, words.view(np.uint8)) for words in evt3_packets()]
    expected = spec_evt3(evt3_packets())
    write_packets(tmp_path / "test_events_ros2_1", 2, "evt3", packets)
    _humble(tmp_path / "test_events_ros2_1", 4, "sqlite3")
    read = read_recording(tmp_path / "test_events_ros2_1")
    assert np.array_equal(read.events, expected)
    assert any(f"{TOPIC}: the bag holds no message definition" in note for note in read.notes)
    write_packets(tmp_path / "test_events_2", 2, "evt3", packets, storage="mcap")
    _humble(tmp_path / "test_events_2", 5, "")
    read = read_recording(tmp_path / "test_events_2")
    assert np.array_equal(read.events, expected)
    assert any("names no storage plugin" in note for note in read.notes)
