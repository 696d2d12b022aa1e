"""Inflating compressed data tofnet did not write, under a bound.

The rule is the ``.npz`` one (``tofnet.io.npy``): ``stored`` compressed bytes may inflate
to ``inflation_limit(stored) = max(MAX_INFLATED_BYTES, MAX_INFLATE_RATIO x stored)``.
``inflate`` decompresses zstd, lz4 frames and bz2 under it: each frame's declared size
(zstd, lz4) is checked before it is inflated, then the data is inflated in steps of at
most 16 MiB and counted, so a refused input never holds more than the limit and a step.
What it returns is what the codec's one-shot ``decompress`` returns for the same data
(zstd: every frame, all of them valid; bz2: every stream, trailing data that is not bz2
ignored; ``lz4.frame``: the first frame). Errors are one line naming ``where``.
"""

from __future__ import annotations

import sys
from typing import Callable, NamedTuple

from tofnet.errors import DataError, located, reason
from tofnet.io.npy import MAX_INFLATE_RATIO, MAX_INFLATED_BYTES

_STEP = 16 * 2**20


def inflation_limit(stored: int) -> int:
    """Most bytes ``stored`` compressed bytes may inflate to (the ``.npz`` rule)."""
    return max(MAX_INFLATED_BYTES, MAX_INFLATE_RATIO * stored)


def too_large(where: object, what: str, size: str, stored: int) -> DataError:
    """The one-line error of ``what`` at ``where`` inflating to ``size`` bytes from ``stored``."""
    return DataError(located(where, None, f"{what} inflates to {size} bytes from {stored:,} (expected at most "
                                          f"{MAX_INFLATED_BYTES // 2**20} MiB, or {MAX_INFLATE_RATIO}x the "
                                          "compressed size beyond that: a zip bomb?)"))


class _Truncated(Exception):
    pass


class _Codec(NamedTuple):
    new: Callable  # a decompressor object: decompress(data, max_length), eof, needs_input, unused_data
    declared: Callable | None  # the size a frame's header declares, or None
    errors: tuple[type[BaseException], ...]
    every_frame: bool  # frames after the first are inflated too (lz4.frame.decompress reads one)
    empty_ok: bool  # no data inflates to nothing (bz2.decompress); else it is truncated


def zstd_module():
    """The zstd module rosbags inflates with: the standard library's from Python 3.14, else its backport."""
    if sys.version_info >= (3, 14):
        from compression import zstd
    else:  # pragma: no cover
        from backports import zstd
    return zstd


def _codec(name: str) -> _Codec:
    if name == "zstd":
        zstd = zstd_module()
        return _Codec(zstd.ZstdDecompressor, lambda view: zstd.get_frame_info(view[:18]).decompressed_size,
                      (zstd.ZstdError,), True, False)
    if name == "lz4":
        import lz4.frame

        return _Codec(lz4.frame.LZ4FrameDecompressor,
                      lambda view: lz4.frame.get_frame_info(bytes(view[:19]))["content_size"] or None,
                      (RuntimeError,), False, False)
    if name == "bz2":
        import bz2

        return _Codec(bz2.BZ2Decompressor, None, (OSError, ValueError, EOFError), True, True)
    raise ValueError(f"no bounded inflation for {name!r}")


def inflate(data: bytes, codec: str, where: object, what: str, limit: int | None = None) -> bytes:
    """``data`` compressed with ``codec`` (``"zstd"``, ``"lz4"`` (frame format) or ``"bz2"``),
    inflated to at most ``limit`` bytes (``inflation_limit(len(data))`` unless given);
    ``DataError`` naming ``where`` and ``what`` when it inflates to more, or is not ``codec`` data."""
    spec = _codec(codec)
    stored = len(data)
    limit = inflation_limit(stored) if limit is None else limit
    parts: list[bytes] = []
    size, rest = 0, memoryview(data)
    try:
        if not rest and not spec.empty_ok:
            raise _Truncated("no data")
        while rest:
            first = not parts
            kept = len(parts), size
            try:
                declared = spec.declared(rest) if spec.declared else None
                if declared is not None and size + declared > limit:
                    raise too_large(where, what, f"{size + declared:,}", stored)
                decompressor, data_in = spec.new(), rest
                while not decompressor.eof:  # in steps: a refused input never holds more than the limit
                    if decompressor.needs_input and not data_in:
                        raise _Truncated("the data ends inside a frame")
                    part = decompressor.decompress(data_in, max_length=min(_STEP, limit - size + 1))
                    data_in = b""
                    size += len(part)
                    parts.append(part)
                    if size > limit:
                        raise too_large(where, what, f"more than {limit:,}", stored)
            except OSError:
                if first or codec != "bz2":
                    raise
                del parts[kept[0]:]  # as bz2.decompress: trailing data that is not bz2 is ignored
                size = kept[1]
                break
            if not spec.every_frame:
                break
            rest = memoryview(decompressor.unused_data or b"")
    except (_Truncated, *spec.errors) as err:
        raise DataError(located(where, None, f"{what} is not {codec} data, or is truncated ({reason(err)})")) from None
    return b"".join(parts)


__all__ = ["inflate", "inflation_limit", "too_large"]
