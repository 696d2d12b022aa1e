"""A ROS 2 bag folder is checked before rosbags reads it (``tofnet.io.rosbag2_checks``).

Found by a safety audit: a storage file that is a FIFO hung ``tofnet info``; a
``compression_mode: FILE`` bag of 33 KB had rosbags inflate 1 GB into ``$TMPDIR``, and a
``compression_mode: MESSAGE`` bag of 61 KB took 2.2 GB of memory, before tofnet said
"not a readable ROS 2 bag". The hostile bags here are rosbags-written bags with one part
replaced; the inflation limit is lowered to 1 MiB so that the bombs stay small.
"""

import os
import sqlite3
import threading
import tracemalloc

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.io import read_recording
from optional import optional

optional("rosbags")

from formats_helpers import pattern_recording  # noqa: E402
from test_io_ros2 import write_bag2  # noqa: E402

LIMIT = 1 << 20
REC = pattern_recording(duration_us=20_000)


@pytest.fixture
def small_limit(monkeypatch):
    import tofnet.io.inflate as inflate  # the rule's home

    monkeypatch.setattr(inflate, "MAX_INFLATED_BYTES", LIMIT)


def _bomb(size, declared):
    """``size`` zero bytes as one zstd frame, with or without the size in its header."""
    from backports import zstd

    if declared:
        return zstd.compress(bytes(size))
    compressor = zstd.ZstdCompressor()
    data = b"".join(compressor.compress(bytes(LIMIT), compressor.CONTINUE) for _ in range(size // LIMIT))
    return data + compressor.flush()


def refused(path, *match):
    with pytest.raises(DataError) as caught:
        read_recording(path)
    message = str(caught.value)
    assert "\n" not in message, message
    for text in match:
        assert text in message, message
    return message


@pytest.mark.parametrize("mode", ["file", "message"])
def test_zstd_compressed_bags_are_still_read(tmp_path, mode, small_limit):
    write_bag2(tmp_path / "bag", REC, compression=mode)
    assert any(p.suffix == ".zstd" for p in (tmp_path / "bag").iterdir()) == (mode == "file")
    read = read_recording(tmp_path / "bag")
    assert np.array_equal(read.events, REC.events)
    assert read.trajectory is not None and len(read.trajectory.times) == len(REC.trajectory.times)


def test_a_storage_file_that_is_a_fifo_is_refused_unread(tmp_path, capsys):
    """rosbags opened it and waited for a writer forever; a watchdog ends the wait when it does."""
    write_bag2(tmp_path / "bag", REC, storage="mcap")
    fifo = next((tmp_path / "bag").glob("*.mcap"))
    fifo.unlink()
    os.mkfifo(fifo)
    done = threading.Event()

    def watchdog():  # a writer that opens and closes: a reader blocked on the FIFO sees its end
        if not done.wait(10):
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
    threading.Thread(target=watchdog, daemon=True).start()
    try:
        refused(tmp_path / "bag", str(fifo), "is a FIFO (named pipe), expected a regular ROS 2 bag storage file")
        assert main(["info", str(tmp_path / "bag")]) == 2
    finally:
        done.set()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "FIFO" in err[0], err


@pytest.mark.parametrize("declared", [True, False], ids=["size-in-header", "streamed"])
def test_a_file_compressed_bomb_is_refused_before_anything_is_inflated_to_disk(tmp_path, monkeypatch, small_limit,
                                                                              declared):
    import rosbags.rosbag2.reader as reader

    write_bag2(tmp_path / "bag", REC, compression="file")
    storage = next((tmp_path / "bag").glob("*.zstd"))
    storage.write_bytes(_bomb(8 * LIMIT, declared))
    made, inflate_into = [], reader.TemporaryDirectory  # where rosbags inflates a FILE-compressed bag

    def spy(*args, **kwargs):
        made.append(1)
        return inflate_into(*args, **kwargs)
    monkeypatch.setattr(reader, "TemporaryDirectory", spy)
    message = refused(tmp_path / "bag", str(storage), "compression_mode FILE", "inflates to",
                      "expected at most 1 MiB")
    assert ("8,388,608 bytes" in message) == declared, message
    assert not made


@pytest.mark.parametrize("declared", [True, False], ids=["size-in-header", "streamed"])
def test_a_message_compressed_bomb_is_refused_within_the_limit(tmp_path, small_limit, declared):
    write_bag2(tmp_path / "bag", REC, compression="message")
    db3 = next((tmp_path / "bag").glob("*.db3"))
    connection = sqlite3.connect(db3)
    topic = connection.execute("SELECT id FROM topics WHERE name='/dvs/events'").fetchone()[0]
    connection.execute("UPDATE messages SET data=? WHERE id=(SELECT MIN(id) FROM messages WHERE topic_id=?)",
                       (_bomb(64 * LIMIT, declared), topic))
    connection.commit()
    connection.close()
    tracemalloc.start()
    try:
        refused(tmp_path / "bag", str(tmp_path / "bag"), "'/dvs/events'", "compression_mode MESSAGE", "inflates to")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 * LIMIT, f"{peak:,} bytes allocated to refuse a message inflating to 64 MiB"


def test_a_message_that_is_not_zstd_is_one_line(tmp_path):
    write_bag2(tmp_path / "bag", REC, compression="message")
    db3 = next((tmp_path / "bag").glob("*.db3"))
    connection = sqlite3.connect(db3)
    connection.execute("UPDATE messages SET data=? WHERE id=1", (b"\x28\xb5\x2f\xfd-truncated",))
    connection.commit()
    connection.close()
    refused(tmp_path / "bag", str(tmp_path / "bag"), "compression_mode MESSAGE", "is not zstd data")
