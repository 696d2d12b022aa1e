"""Prophesee RAW (EVT2, EVT2.1, EVT3) and DAT files, and Event Stream (.es), through faery.

faery (the ``formats`` extra) decodes them in compiled code; tofnet converts its
packets (``t`` µs, ``x``, ``y``, ``on``) to ``EVENT_DTYPE`` chunks; EVT3 events are
decoded by ``tofnet.io.evt3`` instead, which keeps the time base of Prophesee's
specification where faery's clock refuses to go back. Timestamps are kept
as the file has them: an EVT file's clock usually starts where the camera's did (the
real sample starts at 11.2 s), a DAT file's at 0. ``open_faery`` also dispatches
AEDAT4 to ``tofnet.io.aedat``.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, quote, reason
from tofnet.io.extras import require
from tofnet.io.event_source import EventSource

#: Width/height passed to faery when the header has no geometry: the largest it accepts,
#: so no event is refused; the sensor size is then reported as unknown.
_NO_GEOMETRY = (65535, 65535)
#: Bytes per event in DAT files (after the header and the 2-byte type/size record).
_DAT_EVENT_BYTES = 8


def open_faery(path: Path, kind: str) -> EventSource:
    """The source for a file faery reads: ``kind`` is ``aedat4``, ``evt``, ``dat`` or ``es``."""
    require("faery", path)
    if kind == "aedat4":
        from tofnet.io.aedat import AedatSource
        return AedatSource(path)
    return FaerySource(path, kind)


def _geometry_line(path: Path) -> str | None:
    """The header line that states the sensor size (``% geometry WxH`` or ``% format ...;width=..``), if any."""
    with open(path, "rb") as handle:
        for _ in range(1000):
            line = handle.readline(4096)
            if not line.startswith(b"%") or line.rstrip() == b"% end":
                return None
            if b"geometry" in line or b"width=" in line:
                return line.rstrip().decode("latin1")
    return None


class FaerySource(EventSource):
    """EVT2/EVT2.1/EVT3 RAW, DAT and Event Stream files."""

    def __init__(self, path: str | Path, kind: str):
        super().__init__(path)
        from faery.extension import dat, es, evt

        self.format = kind
        fallback = None
        try:
            if kind == "evt":
                with evt.Decoder(self.path, None, None) as decoder:
                    self.detail, self.sensor_size = decoder.version.upper(), tuple(decoder.dimensions)
            elif kind == "dat":
                with dat.Decoder(self.path, None, None) as decoder:
                    self.detail, self.sensor_size = f"{decoder.version.upper()}, {decoder.event_type}", \
                        tuple(decoder.dimensions)
                    if decoder.event_type != "cd":
                        raise DataError(located(self.path, None, f"DAT file of {quote(decoder.event_type)} events; "
                                                                 "expected 'cd' (change detection) events"))
                self.n_events = self._dat_count()
            else:
                with es.Decoder(self.path, 0) as decoder:
                    self.detail, self.sensor_size = f"{decoder.event_type}, v{decoder.version}", \
                        tuple(decoder.dimensions)
                    if decoder.event_type not in ("dvs", "atis"):
                        raise DataError(located(self.path, None, f"Event Stream of {quote(decoder.event_type)} events; "
                                                                 "expected 'dvs' or 'atis'"))
        except RuntimeError as err:
            if "size" not in str(err) or kind == "es":
                raise DataError(located(self.path, None, f"not a readable {kind.upper()} file ({reason(err)})")) from None
            fallback = _NO_GEOMETRY
            stated = _geometry_line(self.path)
            self.notes.append("the header gives no sensor size (width, height)" if stated is None else
                              f"the header's {quote(stated, 60)} is not a sensor size (width, height; at most 65535 "
                              "px a side): taken as unknown")
            if kind == "evt":
                with evt.Decoder(self.path, fallback, None) as decoder:
                    self.detail = decoder.version.upper()
        self._fallback = fallback
        self._geometry = self.sensor_size  # the header's (a sensor size given later widens what EVT3 decodes)
        if kind == "evt":  # EVT3 is read in 2-byte words, EVT2 and EVT2.1 in 4-byte words
            from tofnet.io.evt3 import header_of
            unit = 2 if self.detail == "EVT3" else 4
            self._note_partial((self.path.stat().st_size - header_of(self.path)[0]) % unit, unit)

    def _dat_count(self) -> int | None:
        # A DAT file is a '%' text header, one type byte, one size byte, then 8 bytes per event.
        with open(self.path, "rb") as handle:
            header = 0
            for line in handle:
                if not line.startswith(b"%"):
                    break
                header += len(line)
        size = self.path.stat().st_size - header - 2
        self._note_partial(size % _DAT_EVENT_BYTES if size >= 0 else 0, _DAT_EVENT_BYTES)
        return size // _DAT_EVENT_BYTES if size >= 0 and size % _DAT_EVENT_BYTES == 0 else None

    def _note_partial(self, extra: int, unit: int) -> None:
        """A file whose data does not end on a whole event or word was cut short: the decoders skip the tail."""
        if extra:
            self.notes.append(f"the file ends with {extra} byte{'s' if extra > 1 else ''} of a partial "
                              f"{unit}-byte {'event' if self.format == 'dat' else 'word'} (not read): truncated?")

    def _packets(self, size_hint: int) -> Iterable[np.ndarray]:
        import faery
        from faery.extension import dat, evt

        # EVT and DAT straight from the decoders (fields t, x, y, then polarity: 'on' or
        # DAT's 0/1 'payload'); Event Stream through faery's Decoder, which flips its y axis.
        try:
            if self.format == "evt" and self.detail == "EVT3":
                yield from self._evt3_packets()
            elif self.format == "evt":
                with evt.Decoder(self.path, self._fallback, None) as decoder:
                    for packet in decoder:
                        if "events" in packet:
                            yield packet["events"]
            elif self.format == "dat":
                with dat.Decoder(self.path, self._fallback, None) as decoder:
                    yield from decoder
            else:
                yield from faery.file_decoder.Decoder(self.path, file_type="es", time_range_cache=None)
                self._note_es_tail()
        except RuntimeError as err:
            raise DataError(located(self.path, None, f"cannot decode ({reason(err)})")) from None

    def _note_es_tail(self) -> None:
        """Read to its end, an Event Stream file that stops inside an event was cut short (faery skips it)."""
        from tofnet.io.event_stream_tail import EVENT_BYTES, partial_event_bytes

        extra = partial_event_bytes(self.path, self.detail.split(",")[0])
        if extra:
            self.notes.append(f"the file ends with {extra} byte{'s' if extra > 1 else ''} of a partial "
                              f"{EVENT_BYTES}-byte event (not read): truncated?")

    def _evt3_packets(self) -> Iterable[np.ndarray]:
        """EVT3 with the specification's time base (``tofnet.io.evt3``); a note counts the events
        stamped with their predecessor's time because the stream went back."""
        from tofnet.io.evt3 import clamped_of, decode_file, new_state

        # the header's geometry, widened to a sensor size given over it (a header that states too small a sensor)
        given = [size for size in (self.sensor_size, self.reading_size) if size is not None]
        width, height = (max(sizes) for sizes in zip(self._fallback or self._geometry, *given))
        state = new_state()
        try:
            yield from decode_file(self.path, width, height, state=state)
        except ValueError as err:
            hint = "" if self._fallback else "; if the header's size is wrong, give the sensor's: --sensor-size WxH"
            raise DataError(located(self.path, None, f"cannot decode ({err}){hint}")) from None
        clamped = clamped_of(state)
        if clamped:
            self.notes.append(f"{clamped:,} EVT3 events were stamped earlier than the event before them "
                              "(the time base went back); given that event's time to keep time order")
