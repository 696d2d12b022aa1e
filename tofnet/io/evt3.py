"""Prophesee EVT 3.0 decoded with the time base of Prophesee's specification.

EVT3 is a stream of 16-bit words (little-endian, type in the top 4 bits). The time of an
event is the decoder's 24-bit time base when the event word comes: ``EVT_TIME_HIGH``
sets its upper 12 bits, ``EVT_TIME_LOW`` its lower 12 bits, and a TIME_HIGH smaller than
the one before by at least 2048 is a wrap-around (2**24 µs more). That is how Prophesee's
format page and openeb's decoder (``evt3_decoder.h``) read it. faery's decoder differs in
one point: its clock never goes back, so after a TIME_LOW that is *smaller* than the one
before (a camera may send ``TIME_LOW 811`` then ``TIME_LOW 800`` with no event between)
every event until the clock passes 811 comes out stamped 811, 1-11 µs late. This decoder
keeps the specification's time; an event whose time would still be earlier than the
event before it (a stream that really goes back) gets its predecessor's time, counted in
``clamped``, so events stay in time order. Vectors take their x and polarity from the last
``VECT_BASE_X`` (the specification and openeb; faery also lets an ``EVT_ADDR_X`` move
them). The rest (vector bits past the sensor's width ignored, coordinates outside the
header's geometry refused) is faery's.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numba import njit

import tofnet.numba_cache  # noqa: F401 - before any cached kernel: numba picks its cache key at decoration
from tofnet.errors import DataError, located
from tofnet.events import EVENT_DTYPE

#: Words decoded per block (about 4 ms of decoding, which a live replay waits for): at most 12 events a
#: word (VECT_12), so 0.8 M events (10 MB) at most.
BLOCK_WORDS = 1 << 16

# Decoder state, carried from block to block (an int64 array so the kernel can update it).
_HIGH, _LOW, _LOOPS, _X, _Y, _POL, _LAST, _CLAMPED, _STARTED, _BAD, _BAD_AT = range(11)
_STATE_SIZE = 11


def header_of(path: Path) -> tuple[int, int]:
    """The header's length in bytes (every line starting with ``%``) and its ``% t0`` (µs, 0 without)."""
    length, t0 = 0, 0
    with open(path, "rb") as handle:
        for line in handle:
            if not line.startswith(b"%"):
                break
            length += len(line)
            if line.rstrip() == b"% end":  # Prophesee's last header line: the data may start with '%' (0x25)
                break
            words = line[1:].replace(b";", b" ").split()
            if words and words[0] in (b"t0", b"T0"):
                if len(words) < 2 or not words[1].isdigit() or len(words[1]) > 18:
                    value = words[1][:20].decode("latin1") if len(words) > 1 else ""
                    raise DataError(located(path, None, f"header line '% t0': expected the time base in whole µs "
                                                        f"(0 or more), got {value!r}"))
                t0 = int(words[1])
    return length, t0


def new_state() -> np.ndarray:
    return np.zeros(_STATE_SIZE, dtype=np.int64)


def decode_words(words: np.ndarray, width: int, height: int, t0: int, state: np.ndarray,
                 first_byte: int | None = None) -> np.ndarray:
    """The CD events of ``words`` (uint16, in file order) as ``EVENT_DTYPE`` records (``t`` µs); ``state`` carries the time base, coordinates and counters to the next call.
    Raises ``ValueError`` naming the word (its byte in the file, given ``first_byte``, the block's) when a
    coordinate is outside ``width`` x ``height``."""
    if len(words) == 0:
        return np.empty(0, dtype=EVENT_DTYPE)
    # One kernel signature for every caller: the words read-only (a file's block is np.frombuffer of
    # bytes; the warmer's and a ROS message's are writable), so no run compiles another _decode.
    words = np.ascontiguousarray(words, dtype="<u2")
    if words.flags.writeable:
        words = words.view()
        words.flags.writeable = False
    out = np.empty(12 * len(words), dtype=EVENT_DTYPE)  # pages are touched only where events are written
    count = _decode(words, width, height, t0, state, out["t"], out["x"], out["y"], out["p"])
    if state[_BAD]:
        kind, at = {1: "x", 2: "y"}[int(state[_BAD])], int(state[_BAD_AT])
        where = f"word {at} of the block" if first_byte is None else f"byte {first_byte + 2 * at:,}"
        raise ValueError(f"{kind} {int(words[at]) & 0x7FF} outside the header's {width}x{height} geometry at {where}")
    return out[:count]


@njit(cache=True)
def _decode(words, width, height, t0, state, t, x, y, p):
    """Decode ``words`` into ``t, x, y, p`` from index 0; the number of events. ``state[_BAD]``: 1 for
    an x, 2 for a y outside the geometry (decoding stops there)."""
    high, low, loops = state[_HIGH], state[_LOW], state[_LOOPS]
    cx, cy, pol, last, clamped, started = state[_X], state[_Y], state[_POL], state[_LAST], state[_CLAMPED], \
        state[_STARTED]
    k = 0
    for i in range(len(words)):
        word = np.int64(words[i])
        kind = word >> 12
        value = word & 0xFFF
        now = (loops << 24) + (high << 12) + low + t0
        if kind == 0x0:  # EVT_ADDR_Y (bit 11: master/slave camera)
            if (value & 0x7FF) >= height:
                state[_BAD], state[_BAD_AT] = 2, i
                break
            cy = value & 0x7FF
        elif kind == 0x2:  # EVT_ADDR_X: one event, with its own x and polarity
            if (value & 0x7FF) >= width:
                state[_BAD], state[_BAD_AT] = 1, i
                break
            if started and now < last:
                clamped += 1
                now = last
            t[k], x[k], y[k], p[k] = now, value & 0x7FF, cy, 1 if value & 0x800 else 0
            k += 1
            last, started = now, 1
        elif kind == 0x3:  # VECT_BASE_X: x and polarity of the vectors that follow
            if (value & 0x7FF) >= width:
                state[_BAD], state[_BAD_AT] = 1, i
                break
            cx = value & 0x7FF
            pol = 1 if value & 0x800 else 0
        elif kind == 0x4 or kind == 0x5:  # VECT_12 / VECT_8: a bit per pixel from the base, which moves on
            size = 12 if kind == 0x4 else 8
            room = min(size, width - cx)
            bits = value & ((1 << room) - 1)
            if bits:
                if started and now < last:
                    clamped += 1
                    now = last
                for b in range(size):
                    if bits & (1 << b):
                        t[k], x[k], y[k], p[k] = now, cx + b, cy, pol
                        k += 1
                last, started = now, 1
            cx = min(cx + size, width - 1)
        elif kind == 0x6:  # EVT_TIME_LOW: the lower 12 bits, as they come (the time may go back)
            low = value
        elif kind == 0x8:  # EVT_TIME_HIGH: the upper 12 bits; a drop of half the range or more wraps
            if high >= value + 2048:
                loops += 1
            if value != high:
                low = 0
            high = value
    state[_HIGH], state[_LOW], state[_LOOPS] = high, low, loops
    state[_X], state[_Y], state[_POL], state[_LAST], state[_CLAMPED], state[_STARTED] = cx, cy, pol, last, \
        clamped, started
    return k


def decode_file(path: Path, width: int, height: int, block_words: int = BLOCK_WORDS,
                state: np.ndarray | None = None) -> Iterator[np.ndarray]:
    """The CD events of an EVT3 file, block by block (see ``decode_words``); ``state`` (``new_state()``)
    holds the counters (``clamped_of``) when given."""
    length, t0 = header_of(path)
    state = new_state() if state is None else state
    with open(path, "rb") as handle:
        handle.seek(length)
        while True:
            first_byte = handle.tell()
            data = handle.read(2 * block_words)
            if len(data) < 2:
                return
            words = np.frombuffer(data[:len(data) // 2 * 2], dtype="<u2")
            events = decode_words(words, width, height, t0, state, first_byte)
            if len(events):
                yield events


def clamped_of(state: np.ndarray) -> int:
    """Events the decoder stamped with their predecessor's time because theirs was earlier."""
    return int(state[_CLAMPED])
