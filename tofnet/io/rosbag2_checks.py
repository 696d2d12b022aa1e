"""What a ROS 2 bag folder is checked for before rosbags reads a byte of it.

rosbags opens what ``metadata.yaml`` names by path and inflates zstd without a bound: a
FIFO named as storage hangs it, a ``compression_mode: FILE`` file is inflated in full into
``$TMPDIR`` before anything is checked (33 KB made 1 GB), and each message of a
``compression_mode: MESSAGE`` bag is inflated in full in memory (a 61 KB bag took 2.2 GB).
So, here first:

- ``metadata.yaml`` is a regular file of at most ``MAX_SPEC_BYTES`` (read as rosbags reads it);
- every storage file it names, and every ``.db3``/``.mcap`` in the folder, is a regular file
  (``tofnet.io.files.open_regular``: refused without being read, and noted as an input);
- a ``FILE``-compressed storage file inflates to at most ``max(MAX_INFLATED_BYTES,
  MAX_INFLATE_RATIO x its size)``, the ``.npz`` rule: the zstd frame's declared size is
  checked first, then the data is inflated and counted, never kept, before rosbags
  inflates it into ``$TMPDIR``;
- ``MESSAGE``-compressed messages are inflated by ``inflate_message`` under the same rule
  per message (rosbags is asked for them as stored).

Errors are one line naming the file. The checks see the files as they are when the bag is
opened: rosbags opens them again by name afterwards.
"""

from __future__ import annotations

from pathlib import Path, PurePath

from tofnet.errors import DataError, located, quote, reason
from tofnet.io.files import open_regular, read_text
from tofnet.io.inflate import inflate, inflation_limit, zstd_module
from tofnet.io.inflate import too_large as _too_large
from tofnet.io.safe_yaml import MAX_SPEC_BYTES

zstd = zstd_module()

_STORAGE = "ROS 2 bag storage file"
_READ_STEP = 1 << 20


def check_bag_folder(path: Path) -> str | None:
    """Check a bag folder's files (module docstring); returns ``"message"`` when its
    messages are zstd-compressed one by one (read them with ``inflate_message``), else None.

    Metadata rosbags refuses anyway (a missing key, a wrong type) is left to rosbags.
    """
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    metadata_file = path / "metadata.yaml"
    text = read_text(metadata_file, "ROS 2 bag metadata file", limit=MAX_SPEC_BYTES)
    try:
        metadata = YAML(typ="safe").load(text)["rosbag2_bagfile_information"]
        names = [PurePath(name).name for name in metadata["relative_file_paths"]]  # as rosbags names them
    except (YAMLError, KeyError, TypeError, ValueError, AttributeError):
        names, metadata = [], {}
    named = [path / name for name in names]
    present = sorted(path.glob("*.db3")) + sorted(path.glob("*.mcap"))
    for file in dict.fromkeys(named + present):
        open_regular(file, _STORAGE).close()
    mode = metadata.get("compression_mode") if isinstance(metadata, dict) else None
    mode = mode.lower() if isinstance(mode, str) else None
    if mode not in ("file", "message") or metadata.get("compression_format") != "zstd":
        return None  # uncompressed, or a compression rosbags refuses before reading
    if mode == "file":
        for file in dict.fromkeys(named):
            _check_inflated_file(file)
    return mode if mode == "message" else None


def _check_inflated_file(file: Path) -> None:
    """A ``compression_mode: FILE`` storage file inflates to at most ``inflation_limit`` bytes."""
    what = "zstd-compressed storage file (compression_mode FILE)"
    with open_regular(file, _STORAGE) as handle:
        stored = handle.seek(0, 2)
        handle.seek(0)
        limit = inflation_limit(stored)
        try:
            declared = zstd.get_frame_info(handle.read(18)).decompressed_size
        except zstd.ZstdError as err:
            raise DataError(located(file, None, f"not a {what} ({reason(err)})")) from None
        if declared is not None and declared > limit:
            raise _too_large(file, what, f"{declared:,}", stored)
        handle.seek(0)
        size = 0
        try:
            with zstd.ZstdFile(handle, "rb") as inflated:
                while chunk := inflated.read(_READ_STEP):
                    size += len(chunk)
                    if size > limit:
                        raise _too_large(file, what, f"more than {limit:,}", stored)
        except (zstd.ZstdError, EOFError) as err:
            raise DataError(located(file, None, f"not a {what}, or truncated ({reason(err)})")) from None


def inflate_message(data: bytes, where: str, topic: str) -> bytes:
    """One zstd-compressed message (``compression_mode: MESSAGE``), inflated to at most
    ``inflation_limit(len(data))`` bytes by ``tofnet.io.inflate.inflate``; its frames'
    declared sizes are checked first."""
    return inflate(data, "zstd", where, f"topic {quote(topic)}: a zstd-compressed message (compression_mode MESSAGE)")
