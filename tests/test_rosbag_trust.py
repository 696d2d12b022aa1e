"""Issue 27 item 3, ROS bags: a look-alike message definition and stamps past 10^9 ns are refused.

An EventArray connection whose Event has ``int64 ts`` (the same 8 bytes as ``time``) was
decoded as the standard one (times 10^6 too large); a nanosecond field >= 10^9 was
accepted. Bags are written with rosbags' own writer.
"""

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.io import read_recording
from optional import optional

optional("rosbags")

from formats_helpers import SENSOR, pattern_recording  # noqa: E402
from test_io_rosbag import write_bag  # noqa: E402

EVENTS = pattern_recording(duration_us=20_000).events[:300]
LOOKALIKE = {"dvs_msgs/msg/Event": "uint16 x\nuint16 y\nint64 ts\nbool polarity\n",
             "dvs_msgs/msg/EventArray": "std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n"}


def _store(definitions=None):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from tofnet.io.rosbag import DVS_MSGS

    store = get_typestore(Stores.ROS1_NOETIC)
    types = {}
    for name, text in (definitions or DVS_MSGS).items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def _event_bag(path, *, store, stamp, msgdef=None, md5sum=None):
    """One EventArray message on /dvs/events, events stamped by ``stamp(t_us)``."""
    from rosbags.rosbag1 import Writer

    types = store.types
    header = types["std_msgs/msg/Header"](seq=0, stamp=types["builtin_interfaces/msg/Time"](sec=1, nanosec=0),
                                          frame_id="dvs")
    message = types["dvs_msgs/msg/EventArray"](
        header=header, height=SENSOR[1], width=SENSOR[0],
        events=[types["dvs_msgs/msg/Event"](x=int(e["x"]), y=int(e["y"]), ts=stamp(types, int(e["t"])),
                                            polarity=bool(e["p"])) for e in EVENTS])
    with Writer(path) as writer:
        options = {"msgdef": msgdef, "md5sum": md5sum} if msgdef else {"typestore": store}
        connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", **options)
        writer.write(connection, 1_000_000_000, store.serialize_ros1(message, "dvs_msgs/msg/EventArray"))


def _time(types, us, extra_ns=0):
    return types["builtin_interfaces/msg/Time"](sec=us // 10**6, nanosec=(us % 10**6) * 1000 + extra_ns)


def refused(path, *match):
    with pytest.raises(DataError) as caught:
        read_recording(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message, message
    for text in match:
        assert text in message, message
    return message


def test_the_standard_definition_is_read(tmp_path):
    _event_bag(tmp_path / "ok.bag", store=_store(), stamp=_time)
    assert np.array_equal(read_recording(tmp_path / "ok.bag").events, EVENTS)


def test_an_event_array_with_int64_stamps_is_refused(tmp_path):
    """Decoded as if standard, its times came out 10^6 too large."""
    _event_bag(tmp_path / "int64.bag", store=_store(LOOKALIKE), stamp=lambda types, us: us * 1000)
    refused(tmp_path / "int64.bag", "/dvs/events", "non-standard message definition", "md5sum")


def test_a_definition_text_that_lies_about_its_md5sum_is_refused(tmp_path):
    from tofnet.io.rosbag import typestore

    lookalike = _store(LOOKALIKE)
    text, _ = lookalike.generate_msgdef("dvs_msgs/msg/EventArray", ros_version=1)
    standard = typestore().generate_msgdef("dvs_msgs/msg/EventArray", ros_version=1)[1]
    _event_bag(tmp_path / "spoof.bag", store=lookalike, stamp=lambda types, us: us * 1000, msgdef=text,
               md5sum=standard)
    refused(tmp_path / "spoof.bag", "definition text")


def test_event_nanoseconds_of_a_second_or_more_are_refused(tmp_path):
    _event_bag(tmp_path / "ns.bag", store=_store(), stamp=lambda types, us: _time(types, us, 10**9))
    refused(tmp_path / "ns.bag", "/dvs/events", "nanoseconds", "below 10^9")


def test_pose_stamp_nanoseconds_of_a_second_or_more_are_refused(tmp_path, monkeypatch):
    import test_io_rosbag

    original = test_io_rosbag._time

    def late(store, seconds_or_us, *, us=False):
        stamp = original(store, seconds_or_us, us=us)
        return stamp if us else type(stamp)(sec=stamp.sec, nanosec=stamp.nanosec + 10**9)
    monkeypatch.setattr(test_io_rosbag, "_time", late)
    write_bag(tmp_path / "pose.bag", pattern_recording(duration_us=20_000))
    refused(tmp_path / "pose.bag", "/optitrack/davis", "nanoseconds")


def test_the_command_line_says_it_in_one_line(tmp_path, capsys):
    _event_bag(tmp_path / "int64.bag", store=_store(LOOKALIKE), stamp=lambda types, us: us * 1000)
    assert main(["info", str(tmp_path / "int64.bag")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "non-standard message definition" in err[0]
