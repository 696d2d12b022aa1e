"""ROS1 bags through rosbags: ``dvs_msgs/EventArray`` events with poses, IMU and camera info.

The layout of ECD's original ``slider_depth.bag`` (``/dvs/events``, ``/dvs/camera_info``,
``/dvs/imu``, ``/optitrack/davis``) and of MVSEC's bags. Topics are found by message
type; when a type has several topics, one whose name contains ``left`` wins, else the
first by name (noted). ``topics={"events": ..., "pose": ..., "imu": ..., "camera_info": ...}``
overrides the choice.

rosbags reads the container (chunks, compression, index); EventArray messages are
decoded with numpy straight from their ROS1 serialisation (13 bytes per event), which
is far faster than building one Python object per event. Event times ``sec.nsec``
become µs rounded half up (as ``events.txt`` seconds are); ``nsec`` must be below 10^9.

A bag carries each connection's message definition (its text and md5sum). Every
connection of a topic tofnet reads must have the standard definition of its type (the
md5sum in the bag, and the md5sum of the definition text it carries): a look-alike (an
``EventArray`` whose stamps are ``int64``, the same size) would otherwise be decoded as
the standard one.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, quote, reason
from tofnet.io.extras import require
from tofnet.io.source import EventSource

#: Message types tofnet reads, by role (rosbags spells them the ROS2 way).
ROLES = {"events": "dvs_msgs/msg/EventArray", "pose": "geometry_msgs/msg/PoseStamped",
         "imu": "sensor_msgs/msg/Imu", "camera_info": "sensor_msgs/msg/CameraInfo"}

#: One ``dvs_msgs/Event`` as serialised by ROS1: x, y, ts (sec, nsec), polarity.
_EVENT_WIRE = np.dtype([("x", "<u2"), ("y", "<u2"), ("sec", "<u4"), ("nsec", "<u4"), ("p", "u1")])

#: dvs_msgs definitions (rpg_dvs_ros), registered to deserialise and to write bags.
DVS_MSGS = {
    "dvs_msgs/msg/Event": "uint16 x\nuint16 y\ntime ts\nbool polarity\n",
    "dvs_msgs/msg/EventArray": "std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n",
}


def typestore():
    """A ROS1 Noetic typestore that also knows ``dvs_msgs``."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    types = {}
    for name, text in DVS_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def decode_event_array(raw: bytes | memoryview, where: object = "EventArray") -> tuple[np.ndarray, tuple[int, int]]:
    """A serialised ``dvs_msgs/EventArray``: its events (``EVENT_DTYPE``) and (width, height);
    ``DataError`` naming ``where`` for a stamp whose nanoseconds are not below 10^9."""
    from tofnet.events import EVENT_DTYPE

    buffer = memoryview(raw)
    frame_id_length = int(np.frombuffer(buffer, "<u4", 1, 12)[0])
    offset = 16 + frame_id_length
    height, width, count = (int(v) for v in np.frombuffer(buffer, "<u4", 3, offset))
    wire = np.frombuffer(buffer, _EVENT_WIRE, count, offset + 12)
    bad = np.flatnonzero(wire["nsec"] >= _NSEC_PER_S)
    if bad.size:
        i = int(bad[0])
        raise DataError(located(where, None, f"event {i}: ts nanoseconds {int(wire['nsec'][i])} (expected below 10^9)"))
    events = np.empty(count, dtype=EVENT_DTYPE)
    events["t"] = wire["sec"].astype(np.int64) * 1_000_000 + (wire["nsec"].astype(np.int64) + 500) // 1000
    events["x"], events["y"], events["p"] = wire["x"], wire["y"], wire["p"] != 0
    return events, (width, height)


#: A ``time``'s nanoseconds are below this.
_NSEC_PER_S = 1_000_000_000


def standard_digests(store) -> dict[str, str]:
    """md5sum of the standard definition of each type tofnet reads (ROS1's rule)."""
    return {msgtype: store.generate_msgdef(msgtype, ros_version=1)[1] for msgtype in ROLES.values()}


def definition_digest(connection) -> str | None:
    """md5sum of the definition text a connection carries (None when it cannot be parsed)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    try:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        return store.generate_msgdef(connection.msgtype, ros_version=1)[1]
    except Exception:  # rosbags' parser raises several kinds (and asserts) on a hostile text
        return None


class RosbagSource(EventSource):
    """A ROS1 bag: events from one EventArray topic; poses, IMU and calibration from the others."""

    format = "rosbag1"

    def __init__(self, path: str | Path, topics: dict[str, str] | None = None):
        super().__init__(path)
        require("rosbags", self.path)
        from rosbags.rosbag1 import Reader, ReaderError

        self.reader = Reader(self.path)
        try:
            self.reader.open()
        except (ReaderError, OSError) as err:
            raise DataError(located(self.path, None, f"not a readable ROS1 bag ({reason(err)})")) from None
        try:
            self.topics = self._choose(dict(topics or {}))
            self._check_definitions()
            self._read_side_topics()
        except BaseException:
            self.reader.close()
            raise
        self.detail = f"events on {self.topics['events']}"

    def _choose(self, overrides: dict[str, str]) -> dict[str, str]:
        available = self.reader.topics
        unknown = set(overrides) - set(ROLES)
        if unknown:
            raise DataError(located(self.path, None, f"unknown topic role(s) {', '.join(quote(r, 20) for r in sorted(unknown))}; "
                                                     f"expected {', '.join(ROLES)}"))
        chosen = {}
        for role, msgtype in ROLES.items():
            candidates = sorted(name for name, info in available.items() if info.msgtype == msgtype)
            if role in overrides:
                name = overrides[role]
                if name not in available or available[name].msgtype != msgtype:
                    found = available[name].msgtype if name in available else "no such topic"
                    raise DataError(located(self.path, None, f"topic {quote(name)} for {role}: expected {msgtype}, "
                                                             f"found {found}"))
                chosen[role] = name
            elif candidates:
                namespace = chosen.get("events", "").rsplit("/", 1)[0]
                preferred = [c for c in candidates if namespace and c.startswith(namespace + "/")] or \
                    [c for c in candidates if "left" in c] or candidates
                chosen[role] = preferred[0]
                if len(candidates) > 1:
                    self.notes.append(f"{role}: {chosen[role]} of {', '.join(candidates)} "
                                      f"(choose with --topic {role}=NAME)")
        if "events" not in chosen:
            found = ", ".join(f"{quote(name)} ({quote(info.msgtype)})"
                              for name, info in sorted(available.items())[:10]) or "none"
            raise DataError(located(self.path, None, f"no dvs_msgs/EventArray topic; topics: {found}"))
        for name, info in sorted(available.items()):
            if name not in chosen.values():
                self.streams[name] = f"{info.msgtype}, {info.msgcount} messages"
        return chosen

    def _check_definitions(self) -> None:
        """Every connection of a chosen topic has its type's standard definition (md5sum and text)."""
        digests = standard_digests(typestore())
        for role, topic in self.topics.items():
            for connection in (c for c in self.reader.connections if c.topic == topic):
                expected = digests[ROLES[role]]
                if connection.digest != expected:
                    what = f"md5sum {quote(connection.digest, 40)}"
                elif definition_digest(connection) != expected:  # the text may lie about its md5sum
                    what = "the md5sum of its definition text"
                else:
                    continue
                raise DataError(located(self.path, None, f"topic {quote(topic)}: {ROLES[role]} with a non-standard "
                                                         f"message definition ({what} differs from the standard "
                                                         f"{expected}); not decoded"))

    def _messages(self, role: str):
        connections = [c for c in self.reader.connections if c.topic == self.topics[role]]
        return self.reader.messages(connections=connections)

    def _read_side_topics(self) -> None:
        store = typestore()
        if "camera_info" in self.topics:
            for _, _, raw in self._messages("camera_info"):
                self._camera_info(store.deserialize_ros1(raw, ROLES["camera_info"]))
                break
        if "pose" in self.topics:
            rows = [_pose_row(store.deserialize_ros1(raw, ROLES["pose"]), self._where("pose"))
                    for _, _, raw in self._messages("pose")]
            if len(rows) >= 2:
                from tofnet.io.groundtruth import Trajectory
                rows = np.asarray(rows)
                self.trajectory = Trajectory(rows[:, 0], rows[:, 1:4], rows[:, 4:8],
                                             source=f"{self.path}:{self.topics['pose']}")
        if "imu" in self.topics:
            rows = [_imu_row(store.deserialize_ros1(raw, ROLES["imu"]), self._where("imu"))
                    for _, _, raw in self._messages("imu")]
            self.imu = np.asarray(rows).reshape(-1, 7)
        for _, _, raw in self._messages("events"):
            _, size = decode_event_array(raw, self._where("events"))
            self.sensor_size = self.sensor_size or (size if min(size) > 0 else None)
            break

    def _camera_info(self, info) -> None:
        from tofnet.io.hdf5 import intrinsics_from

        k = np.asarray(info.K if hasattr(info, "K") else info.k, dtype=np.float64)
        coefficients = np.asarray(info.D if hasattr(info, "D") else info.d, dtype=np.float64)
        try:
            self.intrinsics = intrinsics_from([k[0], k[4], k[2], k[5]], coefficients, info.distortion_model or "radtan")
        except ValueError as err:
            raise DataError(located(self.path, None, f"{quote(self.topics['camera_info'])}: {err}")) from None
        if info.width and info.height:
            self.sensor_size = (int(info.width), int(info.height))

    def _where(self, role: str) -> str:
        return f"{self.path}: topic {self.topics[role]}"

    def _packets(self, size_hint: int) -> Iterable[np.ndarray]:
        where = self._where("events")
        for _, _, raw in self._messages("events"):
            events, _ = decode_event_array(raw, where)
            if len(events):
                yield events

    def close(self) -> None:
        self.reader.close()


def _stamp(header, where: str) -> float:
    """A header's stamp in seconds; its nanoseconds must be below 10^9."""
    if not 0 <= header.stamp.nanosec < _NSEC_PER_S:
        raise DataError(located(where, None, f"header stamp nanoseconds {header.stamp.nanosec} (expected below 10^9)"))
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _pose_row(message, where: str) -> list[float]:
    p, q = message.pose.position, message.pose.orientation
    return [_stamp(message.header, where), p.x, p.y, p.z, q.x, q.y, q.z, q.w]


def _imu_row(message, where: str) -> list[float]:
    a, g = message.linear_acceleration, message.angular_velocity
    return [_stamp(message.header, where), a.x, a.y, a.z, g.x, g.y, g.z]
