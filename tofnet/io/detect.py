"""Which format a recording is in, from its first bytes (magic numbers, headers) and its name.

Content decides where a file announces itself (AEDAT4, HDF5, ROS bag, numpy, Event
Stream, the ``%`` header of Prophesee files); the suffix only breaks ties (``.raw``
vs ``.dat`` without a telling header) and names text files.
"""

from __future__ import annotations

import os
from pathlib import Path

from tofnet.errors import DataError, located, quote
from tofnet.io.files import open_regular, present

#: Every format ``read_recording`` knows, with a one-line description (``tofnet info``, docs).
FORMATS = {
    "ecd": "Event Camera Dataset folder (events.txt, calib.txt, groundtruth.txt, imu.txt)",
    "text": "events.txt lines 't x y p' (seconds, column, row, polarity)",
    "npy": "numpy .npy event array",
    "npz": "numpy .npz event arrays",
    "aedat4": "AEDAT4 (iniVation DV)",
    "evt": "Prophesee RAW (EVT2, EVT2.1 or EVT3)",
    "dat": "Prophesee DAT",
    "es": "Event Stream (.es)",
    "hdf5": "HDF5 (DSEC/TUM-VIE, MVSEC or M3ED layout)",
    "rosbag1": "ROS1 bag (dvs_msgs/EventArray, event_camera_msgs/EventPacket)",
    "rosbag2": "ROS 2 bag: a folder with metadata.yaml, or one .db3 (sqlite3) or .mcap file",
}
from tofnet.io.layouts import SEQUENCE_FORMATS  # noqa: E402 (folder layouts: DSEC, MVSEC, TUM-VIE, M3ED)

FORMATS.update(SEQUENCE_FORMATS)

#: What a suffix promises, for the message when the content disagrees.
_SUFFIX_NAMES = {".h5": "HDF5", ".hdf5": "HDF5", ".aedat4": "AEDAT4", ".bag": "a ROS1 bag", ".npy": "numpy",
                 ".db3": "a ROS 2 sqlite3 bag", ".mcap": "MCAP",
                 ".npz": "numpy .npz", ".raw": "Prophesee RAW", ".dat": "Prophesee DAT", ".es": "Event Stream"}
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_EXPECTED = ("an ECD or dataset sequence folder, a ROS 2 bag folder or an events file (.txt, .npy, .npz, .aedat4, "
             ".raw, .dat, .es, .h5/.hdf5, .bag, .db3, .mcap)")
#: ROS 2 storage files: sqlite3 (``.db3``) and MCAP.
_ROSBAG2_MAGIC = (b"SQLite format 3\x00", b"\x89MCAP")


def event_files_in(folder: Path, scanned: int = 10_000, suffixes: tuple[str, ...] | None = None) -> list[str]:
    """Names of the files of ``folder`` whose suffix names an events format (or is one of ``suffixes``; of its first
    ``scanned`` entries), sorted: for the message of a folder that is not a recording but holds some."""
    wanted = set(_SUFFIX_NAMES) if suffixes is None else set(suffixes)
    names = []
    try:
        with os.scandir(folder) as entries:
            for number, entry in enumerate(entries):
                if number >= scanned:
                    break
                if Path(entry.name).suffix.lower() in wanted and entry.is_file(follow_symlinks=False):
                    names.append(entry.name)
    except OSError:
        return []
    return sorted(names)


def detect_format(path: str | Path) -> str:
    """The key of ``FORMATS`` for ``path``; ``DataError`` when it is missing or unknown."""
    path = Path(path)
    if "\x00" in str(path) or not os.path.exists(path):  # os.path: a name too long is "missing", not OSError
        raise DataError(located(path, None, f"no such file or folder; expected {_EXPECTED}"))
    if path.is_dir():
        if present(path / "metadata.yaml", "the ROS 2 bag metadata file"):
            return "rosbag2"
        from tofnet.io.layouts import sequence_kind
        return sequence_kind(path) or "ecd"
    # Only a regular file is read: a FIFO, a device (/dev/zero), a socket is refused unread.
    try:
        with open_regular(path, "recording file") as handle:
            head = handle.read(4096)
            hdf5 = head.startswith(_HDF5_MAGIC) or _hdf5_userblock(handle)
    except OSError as err:
        raise DataError(located(path, None, f"cannot read: {err.strerror or err}")) from None
    suffix = path.suffix.lower()
    if head.startswith(b"#!AER-DAT4"):
        return "aedat4"
    if head.startswith(b"#!AER-DAT"):
        version = head[9:12].decode("ascii", "replace").strip()
        version = version if version.isprintable() else quote(version)
        raise DataError(located(path, None, f"AEDAT {version} is not supported, only AEDAT4; convert it with "
                                            "iniVation DV or jAER to AEDAT4"))
    if hdf5:
        return "hdf5"
    if head.startswith(b"#ROSBAG V2.0"):
        return "rosbag1"
    if head.startswith(_ROSBAG2_MAGIC):
        return "rosbag2"
    if head.startswith(b"#ROSBAG"):
        raise DataError(located(path, None, "only ROS1 bags version 2.0 are supported"))
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if head.startswith(b"PK\x03\x04") or head.startswith(b"PK\x05\x06"):
        return "npz"
    if head.startswith(b"Event Stream"):
        return "es"
    if head.startswith(b"%"):
        return _prophesee_kind(path, head, suffix)
    if suffix in (".txt", ".csv") or _looks_like_event_text(head):
        return "text"
    if not head:
        return _unknown(path, "the file is empty")
    if suffix in _SUFFIX_NAMES:
        return _unknown(path, f"{suffix!r} names {_SUFFIX_NAMES[suffix]} but the content does not start like one")
    return _unknown(path, f"suffix {quote(suffix, 20) if suffix else '(none)'} and content not recognised")


def _hdf5_userblock(handle) -> bool:
    # HDF5 may start after a user block of 512, 1024, 2048, ... bytes.
    offset = 512
    while True:
        handle.seek(offset)
        magic = handle.read(8)
        if len(magic) < 8 or offset > 1 << 20:
            return False
        if magic == _HDF5_MAGIC:
            return True
        offset *= 2


def _prophesee_kind(path: Path, head: bytes, suffix: str) -> str:
    """EVT or DAT from the ``%`` header lines (``% evt 3.0``, ``% format EVT3``, ``% Version 2``)."""
    header = head.decode("latin-1").lower()
    lines = [line[1:].strip() for line in header.splitlines() if line.startswith("%")]
    if any(line.startswith("evt ") or line.startswith("format evt") for line in lines):
        return "evt"
    if any(line.startswith("version") for line in lines):  # DAT's header says its version; a RAW one never does
        return "dat"
    if suffix == ".raw":
        return "evt"
    if suffix == ".dat":
        return "dat"
    return _unknown(path, "a '%' header that is neither Prophesee RAW (% evt) nor DAT (% Version)")


def _looks_like_event_text(head: bytes) -> bool:
    allowed = set(b"0123456789+-.eE \t\r\n#,")
    body = [line for line in head.splitlines() if line.strip() and not line.lstrip().startswith(b"#")]
    return bool(body) and all(set(line) <= allowed for line in body[:5])


def _unknown(path: Path, why: str) -> str:
    raise DataError(located(path, None, f"unknown recording format ({why}); expected {_EXPECTED}"))
