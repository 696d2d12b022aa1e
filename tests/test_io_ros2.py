"""ROS 2 bags (a folder with metadata.yaml, a bare .db3 or .mcap) written with rosbags' rosbag2 writer.

The ECD layout of test_io_rosbag.py in ROS 2 form (``dvs_msgs/msg/EventArray`` in CDR,
``CameraInfo`` with lower-case ``k``/``d``): the events, camera and poses must equal what
the ROS1 bag gives, in sqlite3 and MCAP storage, recognised by content.
"""

import shutil

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.io import read_recording
from tofnet.io.detect import detect_format
from tofnet.io.source import open_recording
from optional import optional

optional("rosbags")

from formats_helpers import INTRINSICS, SENSOR, pattern_recording  # noqa: E402


@pytest.fixture(scope="module")
def recording():
    return pattern_recording(duration_us=60_000)


def _time(types, us=None, seconds=None):
    ns = int(us) * 1000 if us is not None else int(round(seconds * 1e9))
    return types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def write_bag2(path, recording, storage="sqlite3", per_message=400, store=None, event_topic="/dvs/events",
               compression=None):
    """The ECD layout as a ROS 2 bag folder (rosbags' writer, version 9); ``compression``
    ``"file"`` or ``"message"`` compresses it with zstd."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    from tofnet.io.ros_types import typestore

    store = store or typestore(2)
    types = store.types
    header = types["std_msgs/msg/Header"]
    events = recording.events
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    writer = Writer(path, version=9, storage_plugin=plugin)
    if compression:
        writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
    with writer:
        connection = writer.add_connection(event_topic, "dvs_msgs/msg/EventArray", typestore=store)
        for start in range(0, len(events), per_message):
            part = events[start:start + per_message]
            message = types["dvs_msgs/msg/EventArray"](
                header=header(stamp=_time(types, part["t"][0]), frame_id="dvs"), height=SENSOR[1], width=SENSOR[0],
                events=[types["dvs_msgs/msg/Event"](x=int(e["x"]), y=int(e["y"]), ts=_time(types, e["t"]),
                                                    polarity=bool(e["p"])) for e in part])
            writer.write(connection, int(part["t"][0]) * 1000, store.serialize_cdr(message, "dvs_msgs/msg/EventArray"))
        k = INTRINSICS
        info = types["sensor_msgs/msg/CameraInfo"](
            header=header(stamp=_time(types, events["t"][0]), frame_id="dvs"), height=SENSOR[1], width=SENSOR[0],
            distortion_model="plumb_bob", d=np.array(k.distortion), k=np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1.0]),
            r=np.eye(3).ravel(), p=np.zeros(12), binning_x=0, binning_y=0,
            roi=types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        connection = writer.add_connection("/dvs/camera_info", "sensor_msgs/msg/CameraInfo", typestore=store)
        writer.write(connection, int(events["t"][0]) * 1000, store.serialize_cdr(info, "sensor_msgs/msg/CameraInfo"))
        traj = recording.trajectory
        connection = writer.add_connection("/optitrack/davis", "geometry_msgs/msg/PoseStamped", typestore=store)
        for t, p, q in zip(traj.times, traj.positions, traj.quaternions):
            pose = types["geometry_msgs/msg/PoseStamped"](
                header=header(stamp=_time(types, seconds=t), frame_id="world"),
                pose=types["geometry_msgs/msg/Pose"](position=types["geometry_msgs/msg/Point"](*p),
                                                     orientation=types["geometry_msgs/msg/Quaternion"](*q)))
            writer.write(connection, int(round(t * 1e9)), store.serialize_cdr(pose, "geometry_msgs/msg/PoseStamped"))


@pytest.fixture(scope="module", params=["sqlite3", "mcap"])
def bag2(request, tmp_path_factory, recording):
    path = tmp_path_factory.mktemp("ros2") / f"slider_{request.param}"
    write_bag2(path, recording, request.param)
    return path


def test_ros2_bag_folder_reads_events_camera_and_poses(bag2, recording):
    assert detect_format(bag2) == "rosbag2"
    source = open_recording(bag2)
    assert source.format == "rosbag2"
    assert source.topics == {"events": "/dvs/events", "pose": "/optitrack/davis", "camera_info": "/dvs/camera_info"}
    read = source.read()
    assert np.array_equal(read.events, recording.events)
    assert read.intrinsics == INTRINSICS and read.sensor_size == SENSOR
    assert np.allclose(read.trajectory.positions, recording.trajectory.positions)
    assert np.allclose(read.trajectory.times, recording.trajectory.times, rtol=0, atol=1e-6)


def test_a_bare_storage_file_is_recognised_by_content(bag2, recording, tmp_path):
    storage = next(p for p in bag2.iterdir() if p.suffix in (".db3", ".mcap"))
    assert detect_format(storage) == "rosbag2"
    renamed = tmp_path / "recording.bin"  # the content decides, not the suffix
    shutil.copy(storage, renamed)
    assert np.array_equal(read_recording(renamed).events, recording.events)


def test_ros2_and_ros1_bags_give_the_same_events(tmp_path, bag2, recording):
    from test_io_rosbag import write_bag

    write_bag(tmp_path / "same.bag", recording)
    assert np.array_equal(read_recording(tmp_path / "same.bag").events, read_recording(bag2).events)


def test_topic_override_and_window_apply_to_ros2(tmp_path, recording):
    from tofnet.io.window import parse_window

    write_bag2(tmp_path / "stereo", recording, event_topic="/davis/right/events")
    with pytest.raises(DataError, match="topic '/optitrack/davis' for events: expected"):
        open_recording(tmp_path / "stereo", topics={"events": "/optitrack/davis"})
    source = open_recording(tmp_path / "stereo", topics={"events": "/davis/right/events"})
    assert source.topics["events"] == "/davis/right/events"
    window = parse_window("10ms", "20ms", None)
    part = read_recording(tmp_path / "stereo", window=window).events
    t0 = int(recording.events["t"][0])
    inside = recording.events[(recording.events["t"] >= t0 + 10_000) & (recording.events["t"] < t0 + 30_000)]
    assert np.array_equal(part, inside)


def test_a_lookalike_event_array_is_refused_in_one_line(tmp_path, recording, capsys):
    """Event.ts as int64 nanoseconds: the same bytes as builtin_interfaces/Time, another meaning."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.LATEST)
    store.register({**get_types_from_msg("uint16 x\nuint16 y\nint64 ts\nbool polarity\n", "dvs_msgs/msg/Event"),
                    **get_types_from_msg("std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n",
                                         "dvs_msgs/msg/EventArray")})
    from rosbags.rosbag2 import StoragePlugin, Writer

    for storage, plugin in (("db", StoragePlugin.SQLITE3), ("mc", StoragePlugin.MCAP)):
        with Writer(tmp_path / storage, version=9, storage_plugin=plugin) as writer:
            connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
            message = store.types["dvs_msgs/msg/EventArray"](
                header=store.types["std_msgs/msg/Header"](stamp=_time(store.types, 5), frame_id="dvs"),
                height=4, width=4, events=[store.types["dvs_msgs/msg/Event"](x=1, y=2, ts=123_000, polarity=True)])
            writer.write(connection, 1, store.serialize_cdr(message, "dvs_msgs/msg/EventArray"))
        assert main(["info", str(tmp_path / storage)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "non-standard message definition" in err[0] and "/dvs/events" in err[0], err


def test_a_db3_that_is_not_a_bag_is_one_line(tmp_path):
    import sqlite3

    connection = sqlite3.connect(tmp_path / "other.db3")
    connection.execute("CREATE TABLE t (a INTEGER)")
    connection.commit()
    connection.close()
    with pytest.raises(DataError) as caught:
        read_recording(tmp_path / "other.db3")
    assert "\n" not in str(caught.value) and "other.db3" in str(caught.value)


def test_a_bag_without_definitions_is_read_with_a_note(tmp_path):
    """sqlite3 bags before ROS 2 Iron keep no definition and no type hash: nothing to check, said so."""
    import sqlite3

    rec = pattern_recording(duration_us=20_000)
    write_bag2(tmp_path / "humble", rec)
    db3 = next((tmp_path / "humble").glob("*.db3"))
    connection = sqlite3.connect(db3)
    connection.execute("DELETE FROM message_definitions")
    connection.execute("UPDATE topics SET type_description_hash=''")
    connection.commit()
    connection.close()
    read = read_recording(db3)
    assert np.array_equal(read.events, rec.events)
    assert any("/dvs/events: the bag holds no message definition" in note for note in read.notes)
