"""Fuzz targets for the readers of issue 10's formats, through ``read_recording``.

Each target writes one case (the bytes of a file) under the format's usual name and
reads it as a user would, so the shared checks of ``tofnet.io.checks`` (sensor size,
intrinsics, IMU, event times and coordinates) and the translation of the decoding
libraries' errors are exercised with every format. Valid cases are written by the
libraries' own writers (faery, h5py, rosbags); a target whose library is not installed
has no seeds (``format_seeds`` returns ``[]``).

HDF5 is fuzzed in its contents, not its container: a case is a ``.npz`` of the
datasets (``events.t`` for ``events/t``), written into a valid HDF5 file by h5py and
then read. Corrupting the container's bytes reaches libhdf5's own parser, which can
hang inside one C call that no signal interrupts (a corrupted variable-length string,
found on the way), so no in-process fuzz run could survive it.
"""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np

from tofnet.events import EVENT_DTYPE

#: Target name -> (file name, the library it needs).
FORMAT_FILES = {
    "recording.npz": ("rec.npz", "numpy"),
    "aedat4": ("rec.aedat4", "faery"),
    "evt3 (.raw)": ("rec.raw", "faery"),
    "dat": ("rec.dat", "faery"),
    "event stream": ("rec.es", "faery"),
    "hdf5": ("rec.h5", "h5py"),
    "rosbag": ("rec.bag", "rosbags"),
    "rosbag2 (.db3)": ("rec.db3", "rosbags"),
    "rosbag2 (.mcap)": ("rec.mcap", "rosbags"),
    "event packets (.bag)": ("rec.bag", "rosbags"),
}
_SENSOR = (16, 12)


def read_format(name: str):
    """The target ``name``'s run: write the case under the format's name, read it back."""
    file_name = FORMAT_FILES[name][0]

    def run(data: bytes, folder: Path):
        from tofnet.io import read_recording
        path = folder / file_name
        if name == "hdf5":
            _npz_to_hdf5(data, folder, path)
        else:
            path.write_bytes(data)
        return read_recording(path)
    return run


def _npz_to_hdf5(data: bytes, folder: Path, path: Path) -> None:
    """The datasets of a ``.npz`` case written into a fresh HDF5 file.

    Members are read without zip's CRC check (so that an edited value reaches the HDF5
    reader instead of failing the checksum) but through ``tofnet.io.npy``'s checked
    ``.npy`` parser; a case that is not such an archive is a clean ``DataError``.
    """
    import io
    import zipfile

    import h5py

    from tofnet.errors import DataError
    from tofnet.io.npy import _read_array
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        members = [info for info in archive.infolist() if info.filename.endswith(".npy")
                   and info.compress_type == zipfile.ZIP_STORED]
        with h5py.File(path, "w") as out:
            for info in members:
                at = info.header_offset  # the local header's own name and extra lengths
                start = at + 30 + int.from_bytes(data[at + 26:at + 28], "little") + \
                    int.from_bytes(data[at + 28:at + 30], "little")
                raw = data[start:start + info.compress_size]
                array = _read_array(io.BytesIO(raw), len(raw), info.filename)
                if array.dtype.kind == "U":  # h5py stores text as bytes
                    array = np.char.encode(array, "utf-8")
                try:
                    out[info.filename[:-4].replace(".", "/")] = array
                except (TypeError, ValueError, KeyError, OSError):
                    pass  # a dtype or name HDF5 cannot hold: that dataset is absent
    except DataError:
        raise
    except Exception as err:  # noqa: BLE001 - the harness's own zip parsing, not the reader under test
        raise DataError(f"not a case: {type(err).__name__}") from None


def _recording():
    from tofnet.io.groundtruth import Trajectory
    from tofnet.io.recording import Intrinsics, Recording

    events = np.zeros(6, dtype=EVENT_DTYPE)
    events["t"] = [1000, 1500, 2000, 2000, 3500, 9000]
    events["x"], events["y"], events["p"] = [1, 2, 3, 15, 0, 7], [2, 2, 2, 11, 0, 5], [1, 0, 1, 1, 0, 0]
    trajectory = Trajectory([0.0, 0.01], [[0, 0, 0], [0.005, 0, 0]], [[0, 0, 0, 1], [0, 0.01, 0, 1]])
    imu = np.array([[0.0, 0, 0, 9.81, 0, 0, 0], [0.005, 0.1, 0, 9.8, 0.01, 0, 0]])
    return Recording(events=events, intrinsics=Intrinsics(20.0, 21.0, 7.5, 5.5, distortion=(0.1, 0, 0, 0, 0)),
                     trajectory=trajectory, sensor_size=_SENSOR, imu=imu)


@functools.lru_cache(maxsize=None)
def _seed_bytes(name: str) -> tuple[bytes, ...]:
    import importlib.util

    if importlib.util.find_spec(FORMAT_FILES[name][1]) is None:
        return ()
    recording = _recording()
    out = []
    with tempfile.TemporaryDirectory() as scratch:
        path = Path(scratch) / FORMAT_FILES[name][0]
        for variant in _writers(name):
            variant(path, recording)
            out.append(path.read_bytes())
            path.unlink()
    return tuple(out)


def _writers(name: str) -> list:
    if name == "recording.npz":
        from tofnet.io.arrays import write_npz_recording

        def n_imagenet(path, recording):
            events = recording.events
            table = np.zeros(len(events), dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("polarity", "?")])
            for key in ("x", "y", "t"):
                table[key] = events[key]
            table["polarity"] = events["p"] == 1
            np.savez_compressed(path, event_data=table)
        return [write_npz_recording, n_imagenet]
    if name == "hdf5":
        return [_as_npz(_dsec_datasets), _as_npz(_mvsec_datasets)]
    if name == "rosbag":
        return [_write_bag]
    if name.startswith("rosbag2"):
        return [functools.partial(_write_bag2, name.endswith(".mcap)"))]
    if name == "event packets (.bag)":
        return [functools.partial(_write_packets, "evt3"), functools.partial(_write_packets, "mono")]
    if name == "aedat4":
        from tofnet.io.aedat import write_aedat4
        return [lambda path, recording: write_aedat4(path, [recording.events], recording)]
    version = {"evt3 (.raw)": {"version": "evt3"}, "dat": {}, "event stream": {}}[name]
    return [lambda path, recording: _faery_stream(recording).to_file(path, **version)]


def _as_npz(datasets):
    def write(path: Path, recording) -> None:
        with open(path, "wb") as handle:  # a name not ending in .npz: np.savez would add it
            np.savez(handle, **{key.replace("/", "."): value for key, value in datasets(recording).items()})
    return write


def _dsec_datasets(recording) -> dict[str, np.ndarray]:
    """The DSEC layout with tofnet's calib/poses/imu groups."""
    events, k, trajectory, imu = recording.events, recording.intrinsics, recording.trajectory, recording.imu
    return {"events/t": events["t"] - 1000, "events/x": events["x"], "events/y": events["y"],
            "events/p": events["p"], "t_offset": np.int64(1000),
            "ms_to_idx": np.array([0, 3, 5, 5, 5, 5, 5, 5, 5, 6], dtype=np.uint64),
            "calib/resolution": np.array(_SENSOR), "calib/intrinsics": np.array([k.fx, k.fy, k.cx, k.cy]),
            "calib/distortion_coeffs": np.array(k.distortion), "calib/distortion_model": np.array("radtan"),
            "poses/t": trajectory.times, "poses/position": trajectory.positions,
            "poses/quaternion": trajectory.quaternions,
            "imu/t": imu[:, 0], "imu/accel": imu[:, 1:4], "imu/gyro": imu[:, 4:]}


def _mvsec_datasets(recording) -> dict[str, np.ndarray]:
    """MVSEC: ``davis/left/events`` rows x, y, t [s], p [-1/1] and the IMU."""
    events = recording.events
    return {"davis/left/events": np.column_stack([events["x"], events["y"], events["t"] * 1e-6,
                                                  np.where(events["p"] == 1, 1.0, -1.0)]),
            "davis/left/imu": recording.imu[:, 1:], "davis/left/imu_ts": recording.imu[:, 0]}


def _faery_stream(recording):
    import faery

    events = recording.events
    array = np.empty(len(events), dtype=faery.EVENTS_DTYPE)
    array["t"], array["x"], array["y"], array["on"] = events["t"], events["x"], events["y"], events["p"] == 1
    return faery.events_stream_from_array(array, dimensions=_SENSOR)


def _write_bag(path: Path, recording) -> None:
    """Three EventArray messages, a CameraInfo and two poses (the layout of ECD's bags)."""
    from rosbags.rosbag1 import Writer

    from tofnet.io.rosbag import typestore

    store = typestore()
    types = store.types
    header, time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]

    def stamp(us: int):
        return time(sec=us // 1_000_000, nanosec=us % 1_000_000 * 1000)

    events = recording.events
    with Writer(path) as writer:
        connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
        for start in range(0, len(events), 2):
            part = events[start:start + 2]
            message = types["dvs_msgs/msg/EventArray"](
                header=header(seq=start, stamp=stamp(int(part["t"][0])), frame_id="dvs"),
                height=_SENSOR[1], width=_SENSOR[0],
                events=[types["dvs_msgs/msg/Event"](x=int(e["x"]), y=int(e["y"]), ts=stamp(int(e["t"])),
                                                    polarity=bool(e["p"])) for e in part])
            writer.write(connection, int(part["t"][0]) * 1000, store.serialize_ros1(message, "dvs_msgs/msg/EventArray"))
        k = recording.intrinsics
        info = types["sensor_msgs/msg/CameraInfo"](
            header=header(seq=0, stamp=stamp(1000), frame_id="dvs"), height=_SENSOR[1], width=_SENSOR[0],
            distortion_model="plumb_bob", D=np.array(k.distortion), K=np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1.0]),
            R=np.eye(3).ravel(), P=np.zeros(12), binning_x=0, binning_y=0,
            roi=types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        connection = writer.add_connection("/dvs/camera_info", "sensor_msgs/msg/CameraInfo", typestore=store)
        writer.write(connection, 1_000_000, store.serialize_ros1(info, "sensor_msgs/msg/CameraInfo"))
        connection = writer.add_connection("/optitrack/davis", "geometry_msgs/msg/PoseStamped", typestore=store)
        trajectory = recording.trajectory
        for t, p, q in zip(trajectory.times, trajectory.positions, trajectory.quaternions):
            pose = types["geometry_msgs/msg/PoseStamped"](
                header=header(seq=0, stamp=stamp(int(round(t * 1e6))), frame_id="world"),
                pose=types["geometry_msgs/msg/Pose"](position=types["geometry_msgs/msg/Point"](*p),
                                                     orientation=types["geometry_msgs/msg/Quaternion"](*q)))
            writer.write(connection, int(round(t * 1e9)), store.serialize_ros1(pose, "geometry_msgs/msg/PoseStamped"))


def _write_bag2(mcap: bool, path: Path, recording) -> None:
    """The events as ROS 2 ``dvs_msgs/EventArray`` messages (two a message), one storage file."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from tofnet.io.ros_types import typestore

    store = typestore(2)
    types, events = store.types, recording.events
    stamp = [types["builtin_interfaces/msg/Time"](sec=int(t) // 10**6, nanosec=int(t) % 10**6 * 1000) for t in events["t"]]
    folder = path.with_name(path.name + ".d")
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3) as writer:
        connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
        for start in range(0, len(events), 2):
            message = types["dvs_msgs/msg/EventArray"](
                header=types["std_msgs/msg/Header"](stamp=stamp[start], frame_id="dvs"), height=_SENSOR[1],
                width=_SENSOR[0], events=[types["dvs_msgs/msg/Event"](x=int(events["x"][i]), y=int(events["y"][i]),
                                                                     ts=stamp[i], polarity=bool(events["p"][i]))
                                          for i in range(start, min(start + 2, len(events)))])
            writer.write(connection, int(events["t"][start]) * 1000, store.serialize_cdr(message, "dvs_msgs/msg/EventArray"))
    next(folder.glob("*.mcap" if mcap else "*.db3")).rename(path)
    for left in folder.iterdir():
        left.unlink()
    folder.rmdir()


def _write_packets(encoding: str, path: Path, recording) -> None:
    """The events as ROS1 ``event_camera_msgs/EventPacket`` messages (three a message) in ``encoding``."""
    from rosbags.rosbag1 import Writer

    from tofnet.io.ros_types import typestore

    store = typestore(1)
    types, events = store.types, recording.events
    with Writer(path) as writer:
        connection = writer.add_connection("/event_camera/events", "event_camera_msgs/msg/EventPacket", typestore=store)
        for start in range(0, len(events), 3):
            part = events[start:start + 3]
            if encoding == "mono":  # time_base 0, dt in ns
                words = (part["t"].astype(np.uint64) * np.uint64(1000) | part["x"].astype(np.uint64) << np.uint64(32)
                         | part["y"].astype(np.uint64) << np.uint64(48) | part["p"].astype(np.uint64) << np.uint64(63))
            else:  # TIME_HIGH, TIME_LOW, ADDR_Y, ADDR_X per event
                words = np.array([[0x8000 | int(t) >> 12, 0x6000 | int(t) & 0xFFF, int(y), 0x2000 | int(p) << 11 | int(x)]
                                  for t, x, y, p in part], dtype=np.uint16).ravel()
            message = types["event_camera_msgs/msg/EventPacket"](
                header=types["std_msgs/msg/Header"](seq=start, stamp=types["builtin_interfaces/msg/Time"](sec=1, nanosec=0),
                                                    frame_id="event_camera"),
                height=_SENSOR[1], width=_SENSOR[0], seq=start, time_base=0, encoding=encoding, is_bigendian=False,
                events=words.astype(words.dtype.newbyteorder("<")).view(np.uint8))
            writer.write(connection, 1_000_000_000 + start, store.serialize_ros1(message, "event_camera_msgs/msg/EventPacket"))


def format_seeds(name: str) -> list[bytes]:
    """Valid files of target ``name`` (empty when its library is not installed)."""
    return list(_seed_bytes(name))
