"""The ROS message types tofnet reads, their standard definitions, and the check that a bag's are those.

A bag carries each connection's message definition: ROS1 its text and md5sum, ROS 2 its
text (sqlite3 storage from Iron on, MCAP) and/or its RIHS01 type hash (``metadata.yaml``
from version 7, sqlite3 from Iron). Every connection tofnet decodes must carry its type's
standard definition, so that a look-alike (an ``EventArray`` whose stamps are ``int64``,
the same size) is refused instead of decoded as the standard one.
"""

from __future__ import annotations

from functools import lru_cache

#: Message types tofnet reads, by role (rosbags spells them the ROS 2 way). A role may have several.
ROLES = {"events": ("dvs_msgs/msg/EventArray", "event_camera_msgs/msg/EventPacket"),
         "pose": ("geometry_msgs/msg/PoseStamped",), "imu": ("sensor_msgs/msg/Imu",),
         "camera_info": ("sensor_msgs/msg/CameraInfo",)}

#: dvs_msgs (rpg_dvs_ros) in ROS1 spelling (``time``); ROS 2 ports spell it ``builtin_interfaces/Time``.
DVS_MSGS = {
    "dvs_msgs/msg/Event": "uint16 x\nuint16 y\ntime ts\nbool polarity\n",
    "dvs_msgs/msg/EventArray": "std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n",
}
_DVS_MSGS_ROS2 = {**DVS_MSGS, "dvs_msgs/msg/Event": "uint16 x\nuint16 y\nbuiltin_interfaces/Time ts\nbool polarity\n"}

#: event_camera_msgs/EventPacket (ros-event-camera), the same fields in ROS1 and ROS 2.
EVENT_CAMERA_MSGS = {
    "event_camera_msgs/msg/EventPacket": "std_msgs/Header header\nuint32 height\nuint32 width\nuint64 seq\n"
                                         "uint64 time_base\nstring encoding\nbool is_bigendian\nuint8[] events\n",
}


@lru_cache(maxsize=2)
def typestore(ros_version: int = 1):
    """A typestore of ROS1 Noetic (``ros_version=1``) or the latest ROS 2 that also knows
    ``dvs_msgs`` and ``event_camera_msgs``."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.LATEST)
    types = {}
    for name, text in {**(DVS_MSGS if ros_version == 1 else _DVS_MSGS_ROS2), **EVENT_CAMERA_MSGS}.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def standard_digest(msgtype: str, ros_version: int) -> str:
    """ROS1: the md5sum of the standard definition; ROS 2: its RIHS01 hash (the same from Humble to Rolling)."""
    store = typestore(ros_version)
    return store.generate_msgdef(msgtype, ros_version=1)[1] if ros_version == 1 else store.hash_rihs01(msgtype)


def definition_digest(connection, ros_version: int) -> str | None:
    """The digest (as ``standard_digest``) of the definition text a connection carries; None when it
    carries none or it cannot be parsed."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if not connection.msgdef.data:
        return None
    try:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        if ros_version == 1:
            return store.generate_msgdef(connection.msgtype, ros_version=1)[1]
        return store.hash_rihs01(connection.msgtype)
    except Exception:  # rosbags' parser raises several kinds (and asserts) on a hostile text
        return None


def definition_problem(connection, ros_version: int) -> str | None:
    """Why ``connection``'s definition is not the standard one of its type, or None when it is.

    ROS1: the md5sum in the bag and that of its definition text must both be standard.
    ROS 2: the RIHS01 hash (when the bag has one) and that of the definition text (when it
    has one) must be standard; a bag with neither (sqlite3 of Humble and before) cannot be
    checked: ``"unchecked"``.
    """
    expected = standard_digest(connection.msgtype, ros_version)
    name = "md5sum" if ros_version == 1 else "type hash"
    if connection.digest and connection.digest != expected:
        return f"{name} {connection.digest[:40]!r}"
    if ros_version == 1 or connection.msgdef.data:
        if definition_digest(connection, ros_version) != expected:  # the text may lie about its digest
            return f"the {name} of its definition text"
        return None
    return None if connection.digest else "unchecked"
