"""AEDAT4 (iniVation DV) files through faery: events, IMU, and the other streams counted.

An AEDAT4 file interleaves packets of several tracks (events, frames, IMU, triggers).
tofnet reads the first event track (sensor size from its header, event count from the
file's index table) and converts the IMU samples to the ECD convention: seconds,
m/s² (DV stores g) and rad/s (DV stores °/s). The container has to be decoded in file
order, so the IMU is complete once the events have been read (``read()``, or the end
of ``chunks()``). ``write_aedat4`` writes events and IMU back (tests, ``tofnet convert``).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, quote, reason
from tofnet.io.event_source import FIRST_TIMES, EventSource
from tofnet.io.extras import require
from tofnet.io.faery_shared import encoder_error, faery_packet

#: Standard gravity, m/s² per g (DV's accelerometer unit).
GRAVITY = 9.80665
#: What the elements of a track are, for ``streams`` (the index table counts elements: frames, triggers, ...).
_ELEMENTS = {"imus": "samples (read as the IMU)", "frame": "frames", "triggers": "triggers", "events": "events"}
_IMU_FIELDS = ("accelerometer_x", "accelerometer_y", "accelerometer_z", "gyroscope_x", "gyroscope_y", "gyroscope_z")


#: The note of a file that ends inside a packet.
TRUNCATED = "the file ends inside a packet (truncated?): the events of its whole packets were read, the rest is lost"


def _cut_short(err: RuntimeError) -> bool:
    """Whether faery's error is the end of the file inside a packet (Rust's UnexpectedEof)."""
    return "failed to fill whole buffer" in str(err)


class AedatSource(EventSource):
    """An AEDAT4 file; events from its first event track."""

    format = "aedat4"

    def __init__(self, path: str | Path):
        super().__init__(path)
        from faery.extension import aedat

        check_header(self.path)
        try:
            with aedat.Decoder(self.path) as decoder:
                tracks = decoder.tracks()
                try:
                    counts: dict[int, int] = {track.id: 0 for track in tracks}  # a track without packets: 0
                    starts: dict[int, int] = {}
                    ends: dict[int, int] = {}
                    definitions = decoder.file_data_definitions()
                    if not definitions:  # no index table (an interrupted recording): counts unknown
                        raise RuntimeError("no index table")
                    for definition in definitions:
                        counts[definition.track_id] = counts.get(definition.track_id, 0) + definition.elements_count
                        if definition.elements_count:
                            starts[definition.track_id] = min(starts.get(definition.track_id, definition.start_t),
                                                              definition.start_t)
                            ends[definition.track_id] = max(ends.get(definition.track_id, definition.end_t),
                                                            definition.end_t)
                except RuntimeError:
                    counts, starts, ends = {}, {}, {}  # no index table (an interrupted recording): counts unknown
        except RuntimeError as err:
            raise DataError(located(self.path, None, f"not a readable AEDAT4 file ({reason(err)})")) from None
        events = [track for track in tracks if track.data_type == "events"]
        if not events:
            raise DataError(located(self.path, None, "the file has no event track; found "
                                                     + (", ".join(quote(t.data_type, 20) for t in tracks[:10])
                                                        or "no tracks")))
        self.track_id = events[0].id
        self.sensor_size = tuple(events[0].dimensions)
        self.n_events = counts.get(self.track_id)
        self._first_t, self._last_t = starts.get(self.track_id), ends.get(self.track_id)
        self.detail = f"events track {self.track_id}"
        # an IMU track with samples (or an unknown count): a track the index table says is empty is not read
        self._imu_track = any(track.data_type == "imus" and counts.get(track.id) != 0 for track in tracks)
        self._imu_read = False  # metadata()'s pass for the IMU is made once
        self._indexed = bool(counts)  # an index table: the file was closed properly, so it cannot end cut short
        for track in tracks:
            if track.id == self.track_id:
                continue
            count = counts.get(track.id)
            size = f" {track.dimensions[0]}x{track.dimensions[1]}" if track.dimensions else ""
            what = _ELEMENTS.get(track.data_type, "elements")
            name = f"{track.data_type} (track {track.id})"
            shown = f"{count if count is not None else '?'} {what}{size}"
            if track.data_type != "imus":
                self.not_read(name, shown)
            else:
                self.streams[name] = shown

    def _packets(self, size_hint: int) -> Iterable[np.ndarray]:
        from faery.extension import aedat

        imu = []
        try:
            with aedat.Decoder(self.path) as decoder:
                try:
                    for track, packet in decoder:
                        if track.id == self.track_id and len(packet):
                            yield packet
                        elif track.data_type == "imus" and len(packet):
                            imu.append(imu_to_ecd(packet))
                except RuntimeError as err:
                    self._cut_short_or_refuse(err)
        finally:  # also when a time window stops reading early: the IMU read so far, cut to the window
            if imu:
                from tofnet.io.window import window_rows
                rows = np.concatenate(imu)
                self.imu = rows if self.window is None else window_rows(rows, *self.window)

    def _cut_short_or_refuse(self, err: RuntimeError) -> None:
        """A file without an index table that ends inside a packet (an interrupted recording, a copy cut short) is
        read up to there, with a note; any other decoding error (an indexed file's too: a corrupt packet) refuses it."""
        if self._indexed or not _cut_short(err):
            raise DataError(located(self.path, None, f"cannot decode ({reason(err)})")) from None
        if TRUNCATED not in self.notes:
            self.notes.append(TRUNCATED)

    def first_times(self, count: int = FIRST_TIMES) -> np.ndarray:
        imu = self.imu  # decoding the first packet reads the IMU before it: not the recording's whole IMU
        try:
            return super().first_times(count)
        finally:
            self.imu = imu

    def metadata(self, *, imu: bool = True):
        """As ``EventSource.metadata``, with the IMU: the container interleaves it with the events, so a file
        with an IMU track is decoded once more for it (faery decodes every packet; the events are not kept),
        up to the window's end, once per source (a stream of the events, as ``tofnet run`` makes, would
        otherwise build its network without the gyroscope). ``imu`` False: not (``tofnet export``)."""
        if imu and self.imu is None and self._imu_track and not self._imu_read:
            self._read_imu()
        return super().metadata()

    def _read_imu(self) -> None:
        from faery.extension import aedat

        from tofnet.io.window import window_rows
        stop_s = None if self.window is None or self.window[1] is None else self.window[1] * 1e-6
        parts = []
        with aedat.Decoder(self.path) as decoder:
            try:
                for track, packet in decoder:
                    if track.data_type == "imus" and len(packet):
                        parts.append(imu_to_ecd(packet))
                        if stop_s is not None and parts[-1][-1, 0] >= stop_s:
                            break  # a sample at or after the window's end: the rows that cover it are in
            except RuntimeError as err:
                self._cut_short_or_refuse(err)
        self._imu_read = True
        if parts:
            rows = np.concatenate(parts)
            self.imu = rows if self.window is None else window_rows(rows, *self.window)

    def first_time(self) -> int | None:
        # The index table gives each packet's first time: no decoding (a file without it is decoded).
        if self._first_t is not None:
            return self._first_t
        return int(times[0]) if len(times := self.first_times()) else None

    def last_time(self) -> int | None:
        # Likewise the last: each packet's last time is in the index table.
        return self._last_t if self._last_t is not None else super().last_time()


#: Longest AEDAT4 header (its XML description) read: DV writes a few KB.
MAX_HEADER_BYTES = 16 * 2**20


def check_header(path: Path) -> None:
    """Refuse an AEDAT4 file whose header faery cannot decode safely.

    faery 0.7 aborts the whole Python process (a Rust panic that cannot unwind) when the
    header's XML description is not UTF-8; so the header, a flatbuffer ``IOHeader``
    (compression, data table position, description), is checked here first: every
    offset inside the header, the description valid UTF-8.
    """
    import struct

    from tofnet.io.files import open_regular

    def corrupt(why: str) -> DataError:
        return DataError(located(path, None, f"not a readable AEDAT4 file (header: {why})"))

    with open_regular(path, "AEDAT4 file") as handle:
        start = handle.read(18)
        if len(start) < 18 or not start.startswith(b"#!AER-DAT4.0\r\n"):
            raise corrupt("no '#!AER-DAT4.0' line followed by the header size")
        size = struct.unpack("<i", start[14:18])[0]
        if not 12 <= size <= MAX_HEADER_BYTES:
            raise corrupt(f"a size of {size:,} bytes")
        header = handle.read(size)
    if len(header) != size:
        raise corrupt("the file ends inside it")

    def u32(at: int) -> int:
        if not 0 <= at <= size - 4:
            raise corrupt("an offset outside the header")
        return struct.unpack_from("<I", header, at)[0]

    table = u32(0)
    vtable = table - struct.unpack("<i", struct.pack("<I", u32(table)))[0]
    if not 0 <= vtable <= size - 4:
        raise corrupt("an offset outside the header")
    vtable_size = struct.unpack_from("<H", header, vtable)[0]
    if vtable_size < 4 or vtable + vtable_size > size:
        raise corrupt("an offset outside the header")
    if vtable_size >= 10:  # field 2: the description string
        field = struct.unpack_from("<H", header, vtable + 8)[0]
        if field:
            at = table + field
            text = at + u32(at)
            length = u32(text)
            if text + 4 + length > size:
                raise corrupt("a description longer than the header")
            try:
                header[text + 4:text + 4 + length].decode("utf-8")
            except UnicodeDecodeError as err:
                raise corrupt(f"the description is not UTF-8 (byte {err.start})") from None


def imu_to_ecd(packet: np.ndarray) -> np.ndarray:
    """DV IMU samples (µs, g, °/s) as ``(n, 7)`` rows ``t ax ay az gx gy gz`` (s, m/s², rad/s)."""
    out = np.empty((len(packet), 7))
    out[:, 0] = packet["t"] * 1e-6
    for k, name in enumerate(_IMU_FIELDS):
        out[:, 1 + k] = packet[name]
    out[:, 1:4] *= GRAVITY
    out[:, 4:7] *= np.pi / 180.0
    return out


def write_aedat4(path: str | Path, chunks: Iterable[np.ndarray], meta) -> int:
    """Write ``EVENT_DTYPE`` chunks as AEDAT4 (LZ4); returns the event count.

    ``meta`` is a ``Recording`` or ``EventSource``: its ``sensor_size`` is needed first,
    its ``imu`` (ECD rows, converted back to µs, g, °/s) is read after the events, so
    a source's IMU is complete, and written as a second track after them; the track is
    declared only when there is an IMU (``tofnet info`` shows no IMU track of a file
    without one). Times must be >= 0 (AEDAT4 stores unsigned µs).
    """
    require("faery", path, "writing AEDAT4")
    from faery.extension import aedat

    width, height = (int(v) for v in meta.sensor_size)
    tracks = [_track_node(0, "EVTS", "events", {"sizeX": ("int", width), "sizeY": ("int", height)})]
    # An IMU track only with samples: those of the recording, or of an AEDAT4 source, whose IMU comes with its events.
    with_imu = (meta.imu is not None and len(meta.imu) > 0) or (meta.imu is None and getattr(meta, "_imu_track", False))
    if with_imu:
        tracks.append(_track_node(1, "IMUS", "imu", {}))
    description = [aedat.DescriptionNode(name="outInfo", path="/mainloop/Recorder/outInfo/", attributes={},
                                         nodes=tracks)]
    written = 0
    try:
        with aedat.Encoder(path=path, description=description, compression=aedat.LZ4_DEFAULT) as encoder:
            for chunk in chunks:
                if len(chunk) == 0:
                    continue
                if chunk["t"][0] < 0:
                    raise DataError(located(path, None, f"AEDAT4 stores times >= 0 µs, got {int(chunk['t'][0])}"))
                encoder.write(0, faery_packet(chunk))
                written += len(chunk)
            if with_imu and meta.imu is not None:
                for packet in _imu_packets(meta.imu):
                    encoder.write(1, packet)
    except RuntimeError as err:  # faery reports I/O errors as "... (os error N)"
        raise encoder_error(err, path, "AEDAT4") from None
    return written


def _track_node(track: int, type_id: str, name: str, info: dict):
    from faery.extension import aedat

    attributes = {"compression": aedat.DescriptionAttribute(attribute_type="string", value="LZ4"),
                  "originalOutputName": aedat.DescriptionAttribute(attribute_type="string", value=name),
                  "typeIdentifier": aedat.DescriptionAttribute(attribute_type="string", value=type_id)}
    info_attributes = {key: aedat.DescriptionAttribute(attribute_type=kind, value=value)
                       for key, (kind, value) in {**info, "source": ("string", "tofnet")}.items()}
    base = f"/mainloop/Recorder/outInfo/{track}/"
    return aedat.DescriptionNode(name=str(track), path=base, attributes=attributes,
                                 nodes=[aedat.DescriptionNode(name="info", path=base + "info/",
                                                              attributes=info_attributes, nodes=[])])


def _imu_packets(imu: np.ndarray, per_packet: int = 100) -> Iterator[np.ndarray]:
    """ECD IMU rows back to DV samples (µs, g, °/s), ``per_packet`` at a time."""
    dtype = np.dtype([("t", "<u8"), ("temperature", "<f4")] + [(name, "<f4") for name in _IMU_FIELDS]
                     + [(f"magnetometer_{axis}", "<f4") for axis in "xyz"])
    for start in range(0, len(imu), per_packet):
        rows = imu[start:start + per_packet]
        packet = np.zeros(len(rows), dtype=dtype)
        packet["t"] = np.round(rows[:, 0] * 1e6).astype(np.uint64)
        for k, name in enumerate(_IMU_FIELDS):
            packet[name] = rows[:, 1 + k] / (GRAVITY if k < 3 else np.pi / 180.0)
        yield packet

