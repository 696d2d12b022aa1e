"""ROS1 bags in the ECD/MVSEC layout, written with rosbags' own writer."""

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.io import read_recording
from tofnet.io.source import open_recording
from optional import optional

optional("rosbags")

from formats_helpers import INTRINSICS, SENSOR, pattern_recording  # noqa: E402


@pytest.fixture(scope="module")
def recording():
    return pattern_recording(duration_us=100_000)


def _time(store, seconds_or_us, *, us=False):
    total_ns = int(seconds_or_us) * 1000 if us else int(round(seconds_or_us * 1e9))
    return store.types["builtin_interfaces/msg/Time"](sec=total_ns // 10**9, nanosec=total_ns % 10**9)


def write_bag(path, recording, *, event_topics=("/dvs/events",), per_message=500, camera_info=True, k_matrix=None):
    """ECD's slider_depth.bag layout: EventArray, CameraInfo (plumb_bob), Imu, PoseStamped."""
    from rosbags.rosbag1 import Writer

    from tofnet.io.rosbag import typestore

    store = typestore()
    types = store.types
    header = types["std_msgs/msg/Header"]
    events = recording.events
    with Writer(path) as writer:
        for topic in event_topics:
            connection = writer.add_connection(topic, "dvs_msgs/msg/EventArray", typestore=store)
            for start in range(0, len(events), per_message):
                part = events[start:start + per_message]
                message = types["dvs_msgs/msg/EventArray"](
                    header=header(seq=start, stamp=_time(store, part["t"][0], us=True), frame_id="dvs"),
                    height=SENSOR[1], width=SENSOR[0],
                    events=[types["dvs_msgs/msg/Event"](x=int(e["x"]), y=int(e["y"]), ts=_time(store, e["t"], us=True),
                                                        polarity=bool(e["p"])) for e in part])
                writer.write(connection, int(part["t"][0]) * 1000,
                             store.serialize_ros1(message, "dvs_msgs/msg/EventArray"))
        if camera_info:
            k = INTRINSICS
            info = types["sensor_msgs/msg/CameraInfo"](
                header=header(seq=0, stamp=_time(store, events["t"][0], us=True), frame_id="dvs"),
                height=SENSOR[1], width=SENSOR[0], distortion_model="plumb_bob", D=np.array(k.distortion),
                K=np.array(k_matrix if k_matrix is not None else [k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1.0],
                           dtype=np.float64), R=np.eye(3).ravel(),
                P=np.zeros(12), binning_x=0, binning_y=0,
                roi=types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                              do_rectify=False))
            connection = writer.add_connection("/dvs/camera_info", "sensor_msgs/msg/CameraInfo", typestore=store)
            writer.write(connection, int(events["t"][0]) * 1000, store.serialize_ros1(info, "sensor_msgs/msg/CameraInfo"))
        traj = recording.trajectory
        vector = types["geometry_msgs/msg/Vector3"]
        connection = writer.add_connection("/optitrack/davis", "geometry_msgs/msg/PoseStamped", typestore=store)
        for t, p, q in zip(traj.times, traj.positions, traj.quaternions):
            pose = types["geometry_msgs/msg/PoseStamped"](
                header=header(seq=0, stamp=_time(store, t), frame_id="world"),
                pose=types["geometry_msgs/msg/Pose"](position=types["geometry_msgs/msg/Point"](*p),
                                                     orientation=types["geometry_msgs/msg/Quaternion"](*q)))
            writer.write(connection, int(round(t * 1e9)), store.serialize_ros1(pose, "geometry_msgs/msg/PoseStamped"))
        connection = writer.add_connection("/dvs/imu", "sensor_msgs/msg/Imu", typestore=store)
        for row in recording.imu:
            imu = types["sensor_msgs/msg/Imu"](
                header=header(seq=0, stamp=_time(store, row[0]), frame_id="dvs"),
                orientation=types["geometry_msgs/msg/Quaternion"](0, 0, 0, 1), orientation_covariance=np.zeros(9),
                angular_velocity=vector(*row[4:7]), angular_velocity_covariance=np.zeros(9),
                linear_acceleration=vector(*row[1:4]), linear_acceleration_covariance=np.zeros(9))
            writer.write(connection, int(round(row[0] * 1e9)), store.serialize_ros1(imu, "sensor_msgs/msg/Imu"))


@pytest.fixture(scope="module")
def bag(tmp_path_factory, recording):
    path = tmp_path_factory.mktemp("bag") / "slider_depth.bag"
    write_bag(path, recording)
    return path


def test_ecd_bag_layout_reads_events_calibration_poses_imu(bag, recording):
    source = open_recording(bag)
    assert source.topics == {"events": "/dvs/events", "pose": "/optitrack/davis", "imu": "/dvs/imu",
                             "camera_info": "/dvs/camera_info"}
    read = source.read()
    assert np.array_equal(read.events, recording.events)
    assert read.intrinsics == INTRINSICS and read.sensor_size == SENSOR
    assert np.allclose(read.trajectory.positions, recording.trajectory.positions)
    assert np.allclose(read.trajectory.times, recording.trajectory.times, rtol=0, atol=1e-6)
    assert np.allclose(read.imu[:, 1:], recording.imu[:, 1:])


def test_uncalibrated_camera_info_gives_no_intrinsics_and_says_so(tmp_path, recording):
    path = tmp_path / "uncalibrated.bag"
    write_bag(path, recording, k_matrix=np.zeros(9))  # ROS's convention for a camera not calibrated
    source = open_recording(path)
    read = source.read()
    assert read.intrinsics is None and read.sensor_size == SENSOR
    assert any("/dvs/camera_info: the camera matrix is all zeros" in note for note in source.notes)
    broken = tmp_path / "broken.bag"
    write_bag(broken, recording, k_matrix=[-200.0, 0, 120, 0, 200, 90, 0, 0, 1])
    with pytest.raises(DataError, match=r"broken.bag: '/dvs/camera_info': focal lengths must be positive .*fx -200"):
        open_recording(broken).read()


def test_bag_and_events_txt_give_the_same_microseconds(tmp_path, bag, recording):
    from tofnet.io.events import write_events_txt

    write_events_txt(tmp_path / "events.txt", recording.events)
    assert np.array_equal(read_recording(tmp_path / "events.txt").events, read_recording(bag).events)


def test_stereo_bag_prefers_left_and_topics_override(tmp_path, recording):
    path = tmp_path / "stereo.bag"
    write_bag(path, recording, event_topics=("/davis/right/events", "/davis/left/events"), camera_info=False)
    source = open_recording(path)
    assert source.topics["events"] == "/davis/left/events"
    assert any("--topic events=" in note for note in source.notes)
    assert open_recording(path, topics={"events": "/davis/right/events"}).topics["events"] == "/davis/right/events"
    with pytest.raises(DataError, match="topic '/dvs/imu' for events: expected dvs_msgs/msg/EventArray or "
                                        "event_camera_msgs/msg/EventPacket, found "
                                        "sensor_msgs/msg/Imu"):
        open_recording(path, topics={"events": "/dvs/imu"})
    with pytest.raises(DataError, match="unknown topic role"):
        open_recording(path, topics={"depth": "/x"})


def test_bag_without_events_lists_its_topics(tmp_path):
    from rosbags.rosbag1 import Writer

    from tofnet.io.rosbag import typestore

    store = typestore()
    with Writer(tmp_path / "empty.bag") as writer:
        writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
    with pytest.raises(DataError, match="no dvs_msgs/EventArray or event_camera_msgs/EventPacket topic; "
                                        "topics: '/chatter'"):
        read_recording(tmp_path / "empty.bag")
