"""ROS1 and ROS 2 bags through rosbags: events with poses, IMU and camera info.

Events come from ``dvs_msgs/EventArray`` (ROS1, and ROS 2 ports) or
``event_camera_msgs/EventPacket`` (``evt3`` and ``mono``; what the maintained
metavision_driver and libcaer_driver publish), decoded in ``tofnet.io.ros_events``.
ROS1 bags (``#ROSBAG V2.0``), ROS 2 bags (a folder with ``metadata.yaml``, or one
``.db3`` sqlite3 / ``.mcap`` file) are read by rosbags.

Topics are found by message type, as in ECD's ``slider_depth.bag`` (``/dvs/events``,
``/dvs/camera_info``, ``/dvs/imu``, ``/optitrack/davis``) and MVSEC's bags; when a type
has several topics, one in the events' namespace, else one containing ``left``, else the
first by name wins (noted). ``topics={"events": ..., "pose": ..., "imu": ..., "camera_info": ...}``
overrides the choice. Every connection tofnet reads must carry its type's standard
message definition (``tofnet.io.ros_types``); stamps' nanoseconds must be below 10^9.

rosbags inflates each compressed chunk in full before it checks anything (785 bytes of
bz2 in a ROS1 chunk, or 33 KB of zstd in an MCAP chunk, became 1 GiB). tofnet's reads
inflate them with ``tofnet.io.inflate`` under the ``.npz`` rule instead: ROS1 chunks (bz2,
lz4) through the open reader's own chunk table, MCAP chunks (zstd, lz4) through rosbags'
``DECOMPRESSORS`` while tofnet reads (``bounded_chunks``), MCAP chunks overlapping in time
(held at once) under the rule together; the errors name the bag.
"""

from __future__ import annotations

import contextlib
import contextvars
import threading
from collections.abc import Iterable, Iterator
from functools import partial
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, quote, reason
from tofnet.io.extras import require
from tofnet.io.inflate import inflate, inflation_limit, too_large
from tofnet.io.ros_events import _EVENT_WIRE, NSEC_PER_S, PacketDecoder, decode_event_array  # noqa: F401
from tofnet.io.ros_types import DVS_MSGS, ROLES, definition_problem, typestore  # noqa: F401
from tofnet.io.event_source import EventSource

_EVENT_PACKET = "event_camera_msgs/msg/EventPacket"
_SQLITE_MAGIC = b"SQLite format 3\x00"


class RosbagSource(EventSource):
    """A ROS bag: events from one EventArray/EventPacket topic; poses, IMU and calibration from the others."""

    def __init__(self, path: str | Path, topics: dict[str, str] | None = None, kind: str = "rosbag1"):
        super().__init__(path)
        require("rosbags", self.path)
        self.format = kind
        self.ros_version = 1 if kind == "rosbag1" else 2
        self.reader = _open(self.path, kind)
        if getattr(self.reader, "note", None):
            self.notes.append(self.reader.note)
        try:
            self.topics = self._choose(dict(topics or {}))
            self._check_definitions()
            self._read_side_topics()
        except BaseException:
            self.reader.close()
            raise
        self.detail = f"events on {self.topics['events']}" + (f", {self.detail}" if self.detail else "")

    def _types(self, topic: str) -> str | None:
        return self.reader.topics[topic].msgtype

    def _choose(self, overrides: dict[str, str]) -> dict[str, str]:
        available = self.reader.topics
        unknown = set(overrides) - set(ROLES)
        if unknown:
            raise DataError(located(self.path, None, f"unknown topic role(s) {', '.join(quote(r, 20) for r in sorted(unknown))}; "
                                                     f"expected {', '.join(ROLES)}"))
        chosen = {}
        for role, msgtypes in ROLES.items():
            candidates = sorted(name for name, info in available.items() if info.msgtype in msgtypes)
            if role in overrides:
                name = overrides[role]
                if name not in available or available[name].msgtype not in msgtypes:
                    found = available[name].msgtype if name in available else "no such topic"
                    raise DataError(located(self.path, None, f"topic {quote(name)} for {role}: expected "
                                                             f"{' or '.join(msgtypes)}, found {found}"))
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
            raise DataError(located(self.path, None, f"no dvs_msgs/EventArray or event_camera_msgs/EventPacket topic; "
                                                     f"topics: {found}"))
        for name, info in sorted(available.items()):
            if name not in chosen.values():
                self.not_read(name, f"{info.msgtype}, {info.msgcount} messages")
        return chosen

    def _check_definitions(self) -> None:
        """Every connection of a chosen topic has its type's standard definition (digest and text)."""
        from tofnet.io.ros_types import standard_digest

        for topic in self.topics.values():
            for connection in (c for c in self.reader.connections if c.topic == topic):
                problem = definition_problem(connection, self.ros_version)
                if problem == "unchecked":
                    self.notes.append(f"{topic}: the bag holds no message definition of {connection.msgtype} "
                                      "(sqlite3 bags before ROS 2 Iron); decoded as the standard one")
                elif problem:
                    expected = standard_digest(connection.msgtype, self.ros_version)
                    raise DataError(located(self.path, None, f"topic {quote(topic)}: {connection.msgtype} with a "
                                                             f"non-standard message definition ({problem} differs from "
                                                             f"the standard {expected}); not decoded"))

    def _messages(self, role: str):
        connections = [c for c in self.reader.connections if c.topic == self.topics[role]]
        return self.reader.messages(connections=connections)

    def _deserialize(self, raw, msgtype: str):
        store = typestore(self.ros_version)
        return store.deserialize_ros1(raw, msgtype) if self.ros_version == 1 else store.deserialize_cdr(raw, msgtype)

    def _read_side_topics(self) -> None:
        for role, reader in (("camera_info", None), ("pose", _pose_row), ("imu", _imu_row)):
            if role not in self.topics:
                continue
            msgtype = ROLES[role][0]
            if reader is None:
                for _, _, raw in self._messages(role):
                    self._camera_info(self._deserialize(raw, msgtype))
                    break
                continue
            rows = [reader(self._deserialize(raw, msgtype), self._where(role)) for _, _, raw in self._messages(role)]
            if role == "imu":
                self.imu = np.asarray(rows).reshape(-1, 7)
            elif len(rows) >= 2:
                from tofnet.io.groundtruth import Trajectory
                rows = np.asarray(rows)
                self.trajectory = Trajectory(rows[:, 0], rows[:, 1:4], rows[:, 4:8],
                                             source=f"{self.path}:{self.topics['pose']}")
        for _, _, raw in self._messages("events"):
            if self._types(self.topics["events"]) == _EVENT_PACKET:
                message = self._deserialize(raw, _EVENT_PACKET)
                size, encoding = (int(message.width), int(message.height)), str(message.encoding)
                self.detail = f"EventPacket {encoding}"
                if encoding == "evt3" and (self.trajectory is not None or self.imu is not None):
                    self.notes.append("EventPacket evt3 events are on the camera's clock (time_base is not used), "
                                      "poses and IMU on the bag's header stamps")
            else:
                _, size = self._event_array(raw, self._where("events"))
            self.sensor_size = self.sensor_size or (size if min(size) > 0 else None)
            break

    def _event_array(self, raw, where):
        from tofnet.io.ros_events import decode_event_array_cdr
        return decode_event_array(raw, where) if self.ros_version == 1 else decode_event_array_cdr(raw, where)

    def _camera_info(self, info) -> None:
        from tofnet.io.calibration import intrinsics_from

        k = np.asarray(info.K if hasattr(info, "K") else info.k, dtype=np.float64)
        coefficients = np.asarray(info.D if hasattr(info, "D") else info.d, dtype=np.float64)
        if k.size == 9 and not k.any():  # ROS's convention for a camera not calibrated: no intrinsics, say so
            self.notes.append(f"{self.topics['camera_info']}: the camera matrix is all zeros (not calibrated); "
                              "give the calibration with --calib FILE or --intrinsics fx,fy,cx,cy")
            if info.width and info.height:
                self.sensor_size = (int(info.width), int(info.height))
            return
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
        packets = self._types(self.topics["events"]) == _EVENT_PACKET
        decoder = PacketDecoder(where) if packets else None
        for index, (_, _, raw) in enumerate(self._messages("events")):
            if decoder is not None:
                events = decoder.decode(self._deserialize(raw, _EVENT_PACKET), index)
            else:
                events, _ = self._event_array(raw, where)
            if len(events):
                yield events
        if decoder is not None and decoder.untimed:
            self.notes.append(f"{decoder.untimed} EVT3 events before the topic's first time stamp (TIME_HIGH, "
                              "TIME_LOW): not decoded, as event_camera_codecs does")

    def close(self) -> None:
        self.reader.close()


def _open(path: Path, kind: str):
    """An open reader with ``topics``, ``connections``, ``messages(connections=)`` and ``close()``."""
    if kind == "rosbag1":
        from rosbags.rosbag1 import Reader, ReaderError

        reader, errors, what = Reader(path), (ReaderError, OSError), "ROS1 bag"
    else:
        from rosbags.rosbag2 import ReaderError
        from rosbags.rosbag2.reader import DirectoryReader, McapReader, Sqlite3Reader

        from tofnet.io.files import open_regular
        from tofnet.io.rosbag2_checks import check_bag_folder

        def by_content(file: Path):
            with open_regular(file, "ROS 2 bag storage file") as handle:
                return (Sqlite3Reader if handle.read(16) == _SQLITE_MAGIC else McapReader)(file)

        files = sorted(path.glob("*.db3")) + sorted(path.glob("*.mcap")) if path.is_dir() else []
        # rosbags opens the files by name and inflates zstd unbounded: the files (regular, noted
        # as inputs) and FILE compression are checked first, MESSAGE compression is bounded here
        compression = check_bag_folder(path) if path.is_dir() else None
        storage = DirectoryReader(path) if path.is_dir() else by_content(path)
        reader, errors, what = (_Rosbag2(storage, path, compression == "message"),
                                (ReaderError, OSError, KeyError, ValueError), "ROS 2 bag")
    try:
        reader.open()
    except errors as err:
        # metadata.yaml with an empty storage_identifier (as in event_camera_py's MCAP sample): one
        # storage file, read as its content says
        if kind == "rosbag2" and "Storage plugin" in str(err) and len(files) == 1:
            fallback = _open(files[0], kind)
            fallback.note = f"metadata.yaml names no storage plugin: {files[0].name} read as its content says"
            return fallback
        raise DataError(located(path, None, f"not a readable {what} ({reason(err)})")) from None
    if kind == "rosbag1":
        _bound_ros1_chunks(reader, path)
    return reader


def _bound_ros1_chunks(reader, path: Path) -> None:
    """The open ROS1 reader inflates its bz2 and lz4 chunks with ``tofnet.io.inflate``.

    rosbags' ``Reader.open`` binds each chunk to a function of its ``decompressors`` table
    (no declared size is kept, so the limit is the rule applied to the compressed length);
    they are replaced in this reader's chunk table only: nothing global changes.
    """
    from rosbags.rosbag1.reader import decompressors

    codecs = {id(decompressors[name]): name for name in ("bz2", "lz4") if name in decompressors}
    for position, chunk in reader.chunks.items():
        codec = codecs.get(id(chunk.decompressor))
        if codec is not None:
            what = f"the {codec}-compressed chunk at byte {position:,}"
            reader.chunks[position] = chunk._replace(decompressor=partial(inflate, codec=codec, where=path, what=what))


_BAG: contextvars.ContextVar[str | None] = contextvars.ContextVar("tofnet_rosbag_chunks", default=None)
_INSTALLING = threading.Lock()


@contextlib.contextmanager
def bounded_chunks(where: object) -> Iterator[None]:
    """While inside (in this thread or task), MCAP chunks rosbags inflates are inflated by
    ``tofnet.io.inflate`` under the ``.npz`` rule; errors name ``where``.

    rosbags looks its ``DECOMPRESSORS`` table up for each chunk. Its zstd and lz4 entries are
    wrapped once, by a function that calls tofnet's bounded inflation only inside this
    context (a context variable: other threads, and code outside tofnet's reads, get
    rosbags' own functions, unchanged); nesting is allowed.
    """
    _install_mcap_decompressors()
    token = _BAG.set(str(where))
    try:
        yield
    finally:
        _BAG.reset(token)


def _bounded_iter(items: Iterable, where: object) -> Iterator:
    """``items`` (a rosbags generator), each step run inside ``bounded_chunks(where)``."""
    items = iter(items)
    while True:
        with bounded_chunks(where):
            try:
                item = next(items)
            except StopIteration:
                return
        yield item


def _install_mcap_decompressors() -> None:
    from rosbags.rosbag2 import storage_mcap

    table = storage_mcap.DECOMPRESSORS
    if all(hasattr(table.get(codec), "rosbags_decompress") for codec in ("zstd", "lz4")):
        return
    with _INSTALLING:
        for codec in ("zstd", "lz4"):
            current = table.get(codec)
            if current is not None and not hasattr(current, "rosbags_decompress"):
                table[codec] = _mcap_decompressor(codec, current)


def _mcap_decompressor(codec: str, rosbags_decompress):
    def decompress(data: bytes, size: int) -> bytes:
        where = _BAG.get()
        if where is None:  # not tofnet reading: rosbags' own
            return rosbags_decompress(data, size)
        what, limit = f"a {codec}-compressed MCAP chunk", inflation_limit(len(data))
        if size > limit:  # the size its record declares; rosbags compares it after inflating
            raise too_large(where, what, f"{size:,}", len(data))
        return inflate(data, codec, where, what, limit)
    decompress.rosbags_decompress = rosbags_decompress
    return decompress


def _check_overlapping_chunks(chunks, where: object) -> None:
    """rosbags merges an MCAP file's indexed chunks by time: chunks whose time spans overlap
    are inflated and held at once. Each such group, as declared in the chunk index (an MCAP
    chunk inflating to other than its declared size is refused), must inflate to at most
    ``inflation_limit`` of its compressed bytes, the rule for one chunk."""
    import heapq

    live: list[tuple[int, int, int]] = []  # (end time, compressed, inflated) of the chunks held
    stored = inflated = 0
    for chunk in sorted(chunks, key=lambda c: c.message_start_time):
        while live and live[0][0] < chunk.message_start_time:
            _, done_stored, done_inflated = heapq.heappop(live)
            stored, inflated = stored - done_stored, inflated - done_inflated
        heapq.heappush(live, (chunk.message_end_time, chunk.compressed_size, chunk.uncompressed_size))
        stored, inflated = stored + chunk.compressed_size, inflated + chunk.uncompressed_size
        if inflated > inflation_limit(stored):
            what = (f"a {chunk.compression}-compressed MCAP chunk" if len(live) == 1
                    else f"a group of {len(live)} MCAP chunks overlapping in time (read together)")
            raise too_large(where, what, f"{inflated:,}", stored)


class _Rosbag2:
    """rosbags' ROS 2 storage readers (folder, sqlite3 or MCAP file) with rosbag1's ``Reader`` interface."""

    def __init__(self, storage, path: Path, inflate: bool = False):
        self.storage, self.path, self.inflate = storage, path, inflate
        self.topics: dict = {}
        self.note: str | None = None  # how the bag was opened, when unusually

    def open(self) -> None:
        from rosbags.interfaces import TopicInfo

        with bounded_chunks(self.path):  # an MCAP file without a summary is scanned, its chunks inflated
            self.storage.open()
        for storage in getattr(self.storage, "storages", [self.storage]):
            _check_overlapping_chunks(getattr(storage, "chunks", None) or [], self.path)
        if self.inflate:  # rosbags yields MESSAGE-compressed messages as stored; inflate_message bounds them
            self.storage.metadata = self.storage.metadata._replace(compression_mode=None)
        for connection in self.storage.connections:
            info = self.topics.get(connection.topic)
            msgtype = connection.msgtype if info is None or info.msgtype == connection.msgtype else None
            count = connection.msgcount + (info.msgcount if info else 0)
            self.topics[connection.topic] = TopicInfo(msgtype, connection.msgdef, count,
                                                      (info.connections if info else []) + [connection])

    @property
    def connections(self):
        return self.storage.connections

    def messages(self, connections=()):
        messages = _bounded_iter(self.storage.messages(connections or self.storage.connections, None, None),
                                 self.path)
        if not self.inflate:
            return messages
        from tofnet.io.rosbag2_checks import inflate_message
        return ((connection, time, inflate_message(data, str(self.path), connection.topic))
                for connection, time, data in messages)

    def close(self) -> None:
        self.storage.close()


def _stamp(header, where: str) -> float:
    """A header's stamp in seconds; its nanoseconds must be below 10^9."""
    if not 0 <= header.stamp.nanosec < NSEC_PER_S:
        raise DataError(located(where, None, f"header stamp nanoseconds {header.stamp.nanosec} (expected below 10^9)"))
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _pose_row(message, where: str) -> list[float]:
    p, q = message.pose.position, message.pose.orientation
    return [_stamp(message.header, where), p.x, p.y, p.z, q.x, q.y, q.z, q.w]


def _imu_row(message, where: str) -> list[float]:
    a, g = message.linear_acceleration, message.angular_velocity
    return [_stamp(message.header, where), a.x, a.y, a.z, g.x, g.y, g.z]
