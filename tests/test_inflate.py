"""``tofnet.io.inflate``: zstd, lz4 frames and bz2 inflated under the ``.npz`` rule, in steps.

Whatever a codec's one-shot ``decompress`` returns, ``inflate`` returns (frames, trailing
data, empty input), or both refuse; a bomb is refused holding at most the limit and a step.
"""

import bz2
import tracemalloc

import pytest

from tofnet.errors import DataError
from tofnet.io.inflate import inflate, inflation_limit
from optional import optional

optional("rosbags")  # zstd (backports.zstd) and lz4 come with it

import lz4.frame  # noqa: E402
from backports import zstd  # noqa: E402

LIMIT = 1 << 20
DATA = bytes(range(256)) * 300
ONE_SHOT = {"zstd": zstd.decompress, "lz4": lz4.frame.decompress, "bz2": bz2.decompress}


def _streamed(compressor, size):
    """``size`` zero bytes compressed in 1 MiB pieces: no size in the frame's header."""
    return b"".join(compressor.compress(bytes(LIMIT)) for _ in range(size // LIMIT)) + compressor.flush()


def _compress(codec, data):
    return {"zstd": zstd.compress, "lz4": lz4.frame.compress, "bz2": bz2.compress}[codec](data)


def _cases(codec):
    one, two = _compress(codec, DATA), _compress(codec, DATA[:1000])
    return {"one frame": one, "two frames": one + two, "trailing junk": one + b"junk",
            "truncated": one[:-5], "empty": b"", "junk": b"junk" * 10, "empty frame": _compress(codec, b"")}


@pytest.mark.parametrize("codec", ["zstd", "lz4", "bz2"])
def test_inflate_returns_what_one_shot_decompress_returns(codec):
    for name, data in _cases(codec).items():
        try:
            expected = ONE_SHOT[codec](data)
        except Exception:
            expected = None
        try:
            got = inflate(data, codec, "x.bag", "a chunk")
        except DataError as err:
            assert "\n" not in str(err) and str(err).startswith("x.bag: a chunk is not"), str(err)
            got = None
        assert got == expected, f"{codec}, {name}"


def _lz4_streamed(size):
    compressor = lz4.frame.LZ4FrameCompressor()
    head = compressor.begin()  # no content size in the header
    return head + b"".join(compressor.compress(bytes(LIMIT)) for _ in range(size // LIMIT)) + compressor.flush()


def _bomb(codec, size, declared):
    """``size`` zero bytes; ``declared``: with the size in the frame's header (not bz2's)."""
    if declared:
        return _compress(codec, bytes(size))
    if codec == "lz4":
        return _lz4_streamed(size)
    return _streamed(zstd.ZstdCompressor() if codec == "zstd" else bz2.BZ2Compressor(), size)


@pytest.mark.parametrize("declared", [True, False], ids=["size-in-header", "streamed"])
@pytest.mark.parametrize("codec", ["zstd", "lz4", "bz2"])
def test_a_bomb_is_refused_holding_at_most_the_limit(codec, declared, monkeypatch):
    import tofnet.io.inflate as module

    monkeypatch.setattr(module, "MAX_INFLATED_BYTES", LIMIT)
    monkeypatch.setattr(module, "MAX_INFLATE_RATIO", 2)  # lz4 reaches only ~250x
    monkeypatch.setattr(module, "_STEP", LIMIT // 4)
    bomb = _bomb(codec, 64 * LIMIT, declared)
    assert inflation_limit(len(bomb)) == LIMIT
    tracemalloc.start()
    try:
        with pytest.raises(DataError) as caught:
            inflate(bomb, codec, "x.bag", f"a {codec} chunk")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"x.bag: a {codec} chunk inflates to"), message
    assert "expected at most 1 MiB" in message, message
    size_known = declared and codec != "bz2"  # bz2 declares no size
    assert ("67,108,864 bytes" in message) == size_known, message
    assert peak < (LIMIT // 4 if size_known else 3 * LIMIT), f"{peak:,} bytes to refuse 64 MiB of {codec}"


@pytest.mark.parametrize("declared", [True, False], ids=["size-in-header", "streamed"])
@pytest.mark.parametrize("codec", ["zstd", "lz4", "bz2"])
def test_the_limit_is_read_and_one_byte_more_is_not(codec, declared, monkeypatch):
    import tofnet.io.inflate as module

    monkeypatch.setattr(module, "MAX_INFLATED_BYTES", LIMIT)
    assert inflate(_bomb(codec, LIMIT, declared), codec, "x", "y") == bytes(LIMIT)
    with pytest.raises(DataError, match="inflates to"):
        inflate(_bomb(codec, LIMIT, declared), codec, "x", "y", limit=LIMIT - 1)
