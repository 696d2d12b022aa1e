"""Event messages of ROS bags decoded with numpy: ``dvs_msgs/EventArray`` (ROS1 and ROS 2 CDR) and
``event_camera_msgs/EventPacket`` (``evt3`` and ``mono`` encodings).

- **EventArray**, ROS1: 13 bytes per event (x, y u16, ts sec/nsec u32, polarity u8). ROS 2
  (CDR, little-endian): every field aligned to its size from the start of the payload, so
  the first event is laid out ``x@0 y@2 sec@4 nsec@8 p@12`` and each later one, 16 bytes
  apart, ``x@0 y@2 sec@6 nsec@10 p@14``. Stamps ``sec.nsec`` become µs rounded half up.
- **EventPacket ``evt3``**: the ``events`` bytes are Prophesee EVT 3.0 words (little-endian
  16 bit), decoded by ``tofnet.io.evt3`` with its state carried from packet to packet of a
  topic, so the 24-bit µs counter wraps across packets. ``time_base`` is not used (the
  event_camera_msgs documentation: "not used and its content is undefined"; the
  event_camera_codecs decoder ignores it): times are the camera's clock, as in a RAW file.
  As event_camera_codecs does, words before the first TIME_HIGH followed by a TIME_LOW of
  a topic have no time: their events are not decoded, and counted.
- **EventPacket ``mono``**: 8 bytes per event, a little-endian uint64: bits 0-31 ``dt`` (ns),
  32-47 x, 48-62 y, 63 polarity (1 = ON); the time is ``time_base + dt`` ns, rounded to µs
  half up.
"""

from __future__ import annotations

import numpy as np

from tofnet.errors import DataError, located, quote
from tofnet.events import EVENT_DTYPE

#: One ``dvs_msgs/Event`` as serialised by ROS1: x, y, ts (sec, nsec), polarity.
_EVENT_WIRE = np.dtype([("x", "<u2"), ("y", "<u2"), ("sec", "<u4"), ("nsec", "<u4"), ("p", "u1")])
#: The same in CDR: the first event of the sequence, then every later one (16 bytes apart).
_CDR_FIRST = np.dtype({"names": ["x", "y", "sec", "nsec", "p"], "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                       "offsets": [0, 2, 4, 8, 12], "itemsize": 13})
_CDR_LATER = np.dtype({"names": ["x", "y", "sec", "nsec", "p"], "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                       "offsets": [0, 2, 6, 10, 14], "itemsize": 15})

#: A ``time``'s nanoseconds are below this.
NSEC_PER_S = 1_000_000_000
#: EventPacket encodings decoded.
ENCODINGS = ("evt3", "mono")


def _events_from_wire(wire: np.ndarray, where: object) -> np.ndarray:
    bad = np.flatnonzero(wire["nsec"] >= NSEC_PER_S)
    if bad.size:
        i = int(bad[0])
        raise DataError(located(where, None, f"event {i}: ts nanoseconds {int(wire['nsec'][i])} (expected below 10^9)"))
    events = np.empty(len(wire), dtype=EVENT_DTYPE)
    events["t"] = wire["sec"].astype(np.int64) * 1_000_000 + (wire["nsec"].astype(np.int64) + 500) // 1000
    events["x"], events["y"], events["p"] = wire["x"], wire["y"], wire["p"] != 0
    return events


def decode_event_array(raw: bytes | memoryview, where: object = "EventArray") -> tuple[np.ndarray, tuple[int, int]]:
    """A ROS1 ``dvs_msgs/EventArray``: its events (``EVENT_DTYPE``) and (width, height);
    ``DataError`` naming ``where`` for a stamp whose nanoseconds are not below 10^9."""
    buffer = memoryview(raw)
    frame_id_length = int(np.frombuffer(buffer, "<u4", 1, 12)[0])
    offset = 16 + frame_id_length
    height, width, count = (int(v) for v in np.frombuffer(buffer, "<u4", 3, offset))
    return _events_from_wire(np.frombuffer(buffer, _EVENT_WIRE, count, offset + 12), where), (width, height)


def decode_event_array_cdr(raw: bytes | memoryview, where: object = "EventArray") -> tuple[np.ndarray, tuple[int, int]]:
    """A ROS 2 (CDR) ``dvs_msgs/EventArray``, as ``decode_event_array``."""
    buffer = memoryview(raw)
    if len(buffer) < 4 or buffer[1] != 1:
        raise DataError(located(where, None, "not little-endian CDR (the only encoding read)"))
    body = buffer[4:]  # CDR aligns from after the 4-byte encapsulation header
    frame_id_length = int(np.frombuffer(body, "<u4", 1, 8)[0])
    offset = (12 + frame_id_length + 3) // 4 * 4
    height, width, count = (int(v) for v in np.frombuffer(body, "<u4", 3, offset))
    start = offset + 12
    if count == 0:
        return np.empty(0, EVENT_DTYPE), (width, height)
    first = np.frombuffer(body, _CDR_FIRST, 1, start)
    later = np.ndarray((count - 1,), _CDR_LATER, body, start + 14, (16,)) if count > 1 else first[:0]
    wire = np.empty(count, dtype=_EVENT_WIRE)
    for name in _EVENT_WIRE.names:
        wire[name][:1], wire[name][1:] = first[name], later[name]
    return _events_from_wire(wire, where), (width, height)


class PacketDecoder:
    """Decodes the ``EventPacket`` messages of one topic in order (EVT3 keeps its time state)."""

    def __init__(self, where: object):
        from tofnet.io.evt3 import new_state

        self.where = where
        self.encoding: str | None = None
        self.state = new_state()
        self.timed = False  # a TIME_HIGH followed by a TIME_LOW seen (EVT3)
        self.untimed = 0  # EVT3 events before that: not decoded, counted

    def decode(self, message, index: int) -> np.ndarray:
        """The events (``EVENT_DTYPE``) of a deserialised ``EventPacket``, message ``index`` of the topic."""
        where = f"{self.where}, message {index}"
        encoding = str(message.encoding)
        if encoding not in ENCODINGS:
            raise DataError(located(where, None, f"EventPacket encoding {quote(encoding, 20)} is not decoded "
                                                 f"(tofnet reads {', '.join(ENCODINGS)})"))
        if self.encoding not in (None, encoding):
            raise DataError(located(where, None, f"EventPacket encoding {encoding!r} after {self.encoding!r}"))
        self.encoding = encoding
        if message.is_bigendian:
            raise DataError(located(where, None, "EventPacket is_bigendian is true (only little-endian is read)"))
        data = np.asarray(message.events, dtype=np.uint8)
        size = 2 if encoding == "evt3" else 8
        if len(data) % size:
            raise DataError(located(where, None, f"{len(data)} bytes of {encoding} events (expected a multiple of {size})"))
        if encoding == "mono":
            return _mono(data.view("<u8"), int(message.time_base))
        return self._evt3(data.view("<u2"), int(message.width), int(message.height), where)

    def _evt3(self, words: np.ndarray, width: int, height: int, where: str) -> np.ndarray:
        from tofnet.io.evt3 import decode_words

        if not self.timed:
            words = self._skip_untimed(words)
        try:  # a packet without its geometry may hold the EVT3 maximum
            return decode_words(words, width or 2048, height or 2048, 0, self.state)
        except ValueError as err:
            raise DataError(located(where, None, str(err))) from None

    def _skip_untimed(self, words: np.ndarray) -> np.ndarray:
        """event_camera_codecs' rule: nothing has a time before a TIME_HIGH followed by a TIME_LOW; only
        the time words until then count, the events are skipped (and counted)."""
        kinds = words >> 12
        highs = np.flatnonzero(kinds == 0x8)
        lows = np.flatnonzero(kinds == 0x6)
        lows = lows[lows > highs[0]] if highs.size else lows[:0]
        end = int(lows[0]) + 1 if lows.size else len(words)
        head = words[:end]
        self.untimed += _event_count(head)
        self.timed = bool(lows.size)
        from tofnet.io.evt3 import decode_words
        decode_words(head[(head >> 12 == 0x8) | (head >> 12 == 0x6)], 2048, 2048, 0, self.state)
        return words[end:]


def _event_count(words: np.ndarray) -> int:
    """CD events in EVT3 ``words``: one per EVT_ADDR_X, one per set bit of VECT_12 / VECT_8."""
    kinds = words >> 12
    vectors = np.where(kinds == 0x4, words & 0xFFF, np.where(kinds == 0x5, words & 0xFF, 0)).astype(np.uint16)
    bits = np.unpackbits(vectors.view(np.uint8)).sum() if len(vectors) else 0
    return int(np.count_nonzero(kinds == 0x2) + bits)


def _mono(packed: np.ndarray, time_base: int) -> np.ndarray:
    # time_base (ns, up to 2^64) is split so that nothing overflows int64: base_us * 1000 + rest
    base_us, rest = divmod(time_base, 1000)
    events = np.empty(len(packed), dtype=EVENT_DTYPE)
    dt = (packed & np.uint64(0xFFFFFFFF)).astype(np.int64)
    events["t"] = base_us + (rest + dt + 500) // 1000
    events["x"] = (packed >> np.uint64(32)) & np.uint64(0xFFFF)
    events["y"] = (packed >> np.uint64(48)) & np.uint64(0x7FFF)
    events["p"] = packed >> np.uint64(63)
    return events
