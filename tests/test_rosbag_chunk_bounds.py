"""Compressed chunks of ROS1 bags (bz2, lz4) and MCAP files (zstd, lz4) are inflated under
the ``.npz`` rule (``tofnet.io.inflate``), not in full by rosbags.

Found by a safety audit: 785 bytes of bz2 as a ROS1 chunk, or 33 KB of zstd as an MCAP
chunk, took about 2 GB of memory (rosbags inflated 1 GiB, then compared sizes). The bombs
here are bags written by rosbags' writers with the chunk's compressed bytes replaced; the
limit is lowered to 1 MiB (and the ratio to 2x: lz4 reaches only ~250x) so they stay small.
"""

import struct
import threading
import tracemalloc

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.io import read_recording
from optional import optional

optional("rosbags")

import lz4.frame  # noqa: E402
from backports import zstd  # noqa: E402

from formats_helpers import pattern_recording  # noqa: E402
from test_io_ros2 import write_bag2  # noqa: E402
from test_io_rosbag import write_bag  # noqa: E402
from test_rosbag2_bounds import refused  # noqa: E402  (one line, naming what it must)

LIMIT = 1 << 20
BOMB = 64 * LIMIT
REC = pattern_recording(duration_us=20_000)


@pytest.fixture
def small_limit(monkeypatch):
    import tofnet.io.inflate as inflate

    monkeypatch.setattr(inflate, "MAX_INFLATED_BYTES", LIMIT)
    monkeypatch.setattr(inflate, "MAX_INFLATE_RATIO", 2)


def _bomb(codec, size=BOMB):
    """``size`` zero bytes, compressed in 1 MiB pieces: no size in the frame's header."""
    import bz2

    compressor = {"zstd": zstd.ZstdCompressor, "lz4": lz4.frame.LZ4FrameCompressor, "bz2": bz2.BZ2Compressor}[codec]()
    head = compressor.begin() if codec == "lz4" else b""
    return head + b"".join(compressor.compress(bytes(LIMIT)) for _ in range(size // LIMIT)) + compressor.flush()


def write_ros1(path, monkeypatch, codec, compressed=None):
    """``write_bag``'s bag with ``codec`` chunk compression; ``compressed`` replaces every chunk's data."""
    import rosbags.rosbag1

    class Compressing(rosbags.rosbag1.Writer):
        def __init__(self, bag):
            super().__init__(bag)
            self.set_compression(self.CompressionFormat[codec.upper()])
            if compressed is not None:
                self.compressor = lambda data: compressed
    with monkeypatch.context() as patch:
        patch.setattr(rosbags.rosbag1, "Writer", Compressing)
        write_bag(path, REC)
    return path


def write_mcap(path, monkeypatch, codec, compressed=None):
    """``write_bag2``'s MCAP bag with ``codec`` chunk compression (rosbags writes zstd chunks;
    lz4 is its writer with lz4.frame as compressor); ``compressed`` replaces every chunk's data."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.storage_mcap import McapWriter

    class Compressing(McapWriter):
        def __init__(self, *args):
            super().__init__(*args)
            self.compression = codec
            self.compressor = lz4.frame.compress if codec == "lz4" else zstd.compress
            if compressed is not None:
                self.compressor = lambda data: compressed
    with monkeypatch.context() as patch:
        patch.setattr(Writer, "STORAGE_PLUGINS", {**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: Compressing})
        write_bag2(path, REC, storage="mcap", compression="storage")
    return path


def refused_within_limit(path, *match):
    tracemalloc.start()
    try:
        message = refused(path, *match)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 * LIMIT, f"{peak:,} bytes allocated to refuse a chunk inflating to {BOMB:,}"
    return message


@pytest.mark.parametrize("codec", ["bz2", "lz4"])
def test_compressed_ros1_bags_read_as_before(tmp_path, monkeypatch, codec):
    import tofnet.io.rosbag as rosbag

    write_bag(tmp_path / "plain.bag", REC)
    plain = read_recording(tmp_path / "plain.bag")
    bag = write_ros1(tmp_path / "chunks.bag", monkeypatch, codec)
    assert f"compression={codec}".encode() in bag.read_bytes()
    calls, bounded = [], rosbag.inflate

    def spy(data, **kwargs):
        calls.append(kwargs["codec"])
        return bounded(data, **kwargs)
    monkeypatch.setattr(rosbag, "inflate", spy)
    read = read_recording(bag)
    assert calls and set(calls) == {codec}
    assert np.array_equal(read.events, plain.events) and np.array_equal(read.events, REC.events)
    assert np.array_equal(read.trajectory.positions, plain.trajectory.positions)
    assert np.array_equal(read.imu, plain.imu) and read.intrinsics == plain.intrinsics


@pytest.mark.parametrize("codec", ["zstd", "lz4"])
def test_compressed_mcap_chunks_read_as_before(tmp_path, monkeypatch, codec):
    import tofnet.io.rosbag as rosbag

    write_bag2(tmp_path / "plain", REC, storage="mcap")
    plain = read_recording(tmp_path / "plain")
    bag = write_mcap(tmp_path / "chunks", monkeypatch, codec)
    assert codec.encode() in next(bag.glob("*.mcap")).read_bytes()
    calls, bounded = [], rosbag.inflate

    def spy(data, name, *args):
        calls.append(name)
        return bounded(data, name, *args)
    monkeypatch.setattr(rosbag, "inflate", spy)
    read = read_recording(bag)
    assert calls and set(calls) == {codec}
    assert np.array_equal(read.events, plain.events) and np.array_equal(read.events, REC.events)
    assert np.array_equal(read.trajectory.positions, plain.trajectory.positions)


@pytest.mark.parametrize("codec", ["bz2", "lz4"])
def test_a_ros1_chunk_bomb_is_refused_within_the_limit(tmp_path, monkeypatch, small_limit, codec):
    bag = write_ros1(tmp_path / "bomb.bag", monkeypatch, codec, compressed=_bomb(codec))
    refused_within_limit(bag, str(bag), f"the {codec}-compressed chunk at byte ", "inflates to more than 1,048,576",
                         "expected at most 1 MiB")


def _unindexed(bag):
    """The footer says there is no summary: rosbags scans the file (inflating chunks in ``open``)."""
    mcap = next(bag.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    data[-37 + 9:-37 + 17] = bytes(8)
    mcap.write_bytes(bytes(data))
    return bag


@pytest.mark.parametrize("codec", ["zstd", "lz4"])
def test_an_unindexed_mcap_file_reads_as_before(tmp_path, monkeypatch, codec):
    bag = _unindexed(write_mcap(tmp_path / "chunks", monkeypatch, codec))
    assert np.array_equal(read_recording(bag).events, REC.events)


@pytest.mark.parametrize("indexed", [True, False], ids=["indexed", "scanned"])
@pytest.mark.parametrize("codec", ["zstd", "lz4"])
def test_an_mcap_chunk_bomb_is_refused_within_the_limit(tmp_path, monkeypatch, small_limit, codec, indexed):
    bag = write_mcap(tmp_path / "bomb", monkeypatch, codec, compressed=_bomb(codec))
    if not indexed:
        _unindexed(bag)
    refused_within_limit(bag, str(bag), f"a {codec}-compressed MCAP chunk", "inflates to more than 1,048,576",
                         "expected at most 1 MiB")


@pytest.mark.parametrize("indexed", [True, False], ids=["indexed", "scanned"])
def test_an_mcap_chunk_declaring_too_much_is_refused_before_inflating(tmp_path, monkeypatch, small_limit, indexed):
    """The chunk's record (and the summary's chunk index) declare 64 MiB: refused at once
    (indexed: from the index when the bag is opened; scanned: from the record)."""
    import tofnet.io.rosbag as rosbag

    bag = write_mcap(tmp_path / "declared", monkeypatch, "zstd")
    mcap = next(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    at = 8  # after the magic: records of an opcode, a uint64 length and the content
    while data[at] != 0x06:
        at += 9 + struct.unpack_from("<Q", data, at + 1)[0]
    size = data[at + 9 + 16:at + 9 + 24]  # after message_start_time and message_end_time
    assert data.count(size) == 2, "the chunk record and its index"
    mcap.write_bytes(data.replace(size, struct.pack("<Q", BOMB)))
    if not indexed:
        _unindexed(bag)
    monkeypatch.setattr(rosbag, "inflate", lambda *args: pytest.fail("inflated"))
    refused_within_limit(bag, str(bag), "a zstd-compressed MCAP chunk inflates to 67,108,864 bytes")


def test_rosbags_is_unchanged_outside_tofnets_reads(tmp_path, monkeypatch, small_limit):
    """The user's own rosbags code, and other threads while tofnet reads, get rosbags' own
    decompression (a bomb is inflated in full, then its size compared, as before)."""
    import rosbags.rosbag1.reader as ros1
    from rosbags.rosbag2 import ReaderError
    from rosbags.rosbag2 import storage_mcap
    from rosbags.rosbag2.reader import Reader

    import tofnet.io.rosbag as rosbag

    ros1_table = dict(ros1.decompressors)
    bag = write_mcap(tmp_path / "bomb", monkeypatch, "zstd", compressed=_bomb("zstd", 8 * LIMIT))
    refused(bag, "MCAP chunk")
    assert ros1.decompressors == ros1_table
    with Reader(bag) as reader, pytest.raises(ReaderError, match="expected .* got 8388608"):
        list(reader.messages())
    inflated = []
    with rosbag.bounded_chunks(bag):
        with pytest.raises(DataError, match="inner"), rosbag.bounded_chunks("inner"):
            storage_mcap.DECOMPRESSORS["zstd"](_bomb("zstd", 8 * LIMIT), 100)
        with pytest.raises(DataError, match=str(bag)):  # re-entered and left: the outer bag again
            storage_mcap.DECOMPRESSORS["zstd"](_bomb("zstd", 8 * LIMIT), 100)
        other = threading.Thread(target=lambda: inflated.append(
            len(storage_mcap.DECOMPRESSORS["zstd"](_bomb("zstd", 8 * LIMIT), 100))))
        other.start()
        other.join()
    assert inflated == [8 * LIMIT]
    assert len(storage_mcap.DECOMPRESSORS["lz4"](_bomb("lz4", 8 * LIMIT), 100)) == 8 * LIMIT


def _overlapping_mcap(path, overlapping):
    """An MCAP bag of zstd chunks of ~1 MiB of zeros (rosbags closes a chunk past 1 MiB), each
    spanning the same 16 ns when ``overlapping``, one after the other otherwise."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    from tofnet.io.ros_types import typestore

    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        connection = writer.add_connection("/dvs/imu", "sensor_msgs/msg/Imu", typestore=typestore(2))
        for index in range(5 * 17):
            writer.write(connection, 1 + (index % 17 if overlapping else index), bytes(1 << 16))
    return path


def test_mcap_chunks_overlapping_in_time_may_not_inflate_past_the_limit_together(tmp_path, monkeypatch):
    """rosbags merges chunks by time, holding overlapping ones at once: 5 chunks of 1.1 MB,
    each within a 4 MiB limit, overlapping, are refused at open; one after the other, not."""
    import tofnet.io.inflate as inflate
    from rosbags.rosbag2.reader import DirectoryReader

    monkeypatch.setattr(inflate, "MAX_INFLATED_BYTES", 4 * LIMIT)
    monkeypatch.setattr(inflate, "MAX_INFLATE_RATIO", 2)
    bag = _overlapping_mcap(tmp_path / "overlapping", True)
    reader = DirectoryReader(bag)
    reader.open()
    chunks = list(reader.storages[0].chunks)
    reader.close()
    assert len(chunks) >= 5 and all(c.uncompressed_size < 4 * LIMIT for c in chunks)
    assert max(c.message_start_time for c in chunks[:-1]) < min(c.message_end_time for c in chunks[:-1])
    refused(bag, str(bag), "MCAP chunks overlapping in time (read together) inflates to", "expected at most 4 MiB")
    sequential = _overlapping_mcap(tmp_path / "sequential", False)
    refused(sequential, "no dvs_msgs/EventArray or event_camera_msgs/EventPacket topic")  # opened and read
