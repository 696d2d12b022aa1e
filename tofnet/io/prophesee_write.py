"""Prophesee RAW (EVT3) and DAT (DAT2) files, and Event Stream (.es), written through faery's encoders.

``write_prophesee`` writes ``EVENT_DTYPE`` chunks one at a time (bounded memory) and returns the
count; ``tofnet.io.convert`` calls it inside ``atomic_path``. Times are kept exactly, as
``tofnet.io.prophesee`` (and faery's decoders) read them back:

- EVT3 and DAT store times from the first event on, that event's time in a ``% t0`` (``% T0``)
  header line (faery's ``zero_t0``; both readers add it back). Written with absolute times
  instead, an EVT3 file would start with 8 bytes of time words per 2**24 µs of clock (760 MB
  for a Unix-epoch clock) and a DAT file could not hold a first time past 2**32 µs.
- DAT's times are 32-bit; a reader tells a wrap-around from a step back by its size, so two
  consecutive events must be less than ``DAT_MAX_GAP_US`` apart.
- Event Stream has no start time: it stores times from 0 as increments, one byte per 127 µs
  without events, so times are kept below ``ES_MAX_TIME_US`` (the file would grow by 34 MB for
  every 2**32 µs, 71.6 min, of clock). Its rows are flipped (y up), as faery writes and reads it.

Every chunk is checked before faery sees it (times >= 0 and in order, pixels inside the sensor):
faery 0.7's EVT3 encoder, given a time earlier than the file's first, writes time words without end.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.extras import require
from tofnet.io.faery_shared import encoder_error, faery_packet

#: Output kind (``tofnet.io.convert.OUTPUTS``) -> its name in messages.
NAMES = {"evt3": "EVT3", "dat": "DAT", "es": "Event Stream"}
#: Largest sensor side (pixels) each addresses: EVT3 coordinates have 11 bits, faery's DAT
#: encoder takes sides below 16384, Event Stream's are 16-bit.
MAX_SIDE = {"evt3": 2048, "dat": 16383, "es": 65535}
#: Largest time between two consecutive events in a DAT file (µs; half its 32-bit clock).
DAT_MAX_GAP_US = 2**31
#: Event Stream times are kept below this (µs, 71.6 min; see the module docstring).
ES_MAX_TIME_US = 2**32
_DAT_DTYPE = np.dtype([("t", "=u8"), ("x", "=u2"), ("y", "=u2"), ("payload", "u1")])


def write_prophesee(path: str | Path, chunks: Iterable[np.ndarray], meta, kind: str) -> int:
    """Write ``EVENT_DTYPE`` chunks (time-ordered, ``t`` µs >= 0) as ``kind`` (``evt3``, ``dat`` or
    ``es``); returns the event count. ``meta.sensor_size`` (width, height px) goes in the header;
    every event must be inside it. A time the format cannot hold is a one-line ``DataError``."""
    require("faery", path, f"writing {NAMES[kind]}")
    from faery.extension import dat, es, evt

    name = NAMES[kind]
    width, height = (int(v) for v in meta.sensor_size)
    if max(width, height) > MAX_SIDE[kind]:
        raise DataError(located(path, None, f"{name} holds sensors up to {MAX_SIDE[kind]} pixels a side; "
                                            f"the recording's is {width}x{height}"))
    written, last = 0, None
    try:
        if kind == "evt3":
            encoder = evt.Encoder(path=path, version="evt3", zero_t0=True, dimensions=(width, height),
                                  enforce_monotonic=True)
        elif kind == "dat":
            encoder = dat.Encoder(path=path, version="dat2", event_type="cd", zero_t0=True,
                                  dimensions=(width, height))
        else:
            encoder = es.Encoder(path=path, event_type="dvs", zero_t0=False, dimensions=(width, height))
        with encoder:
            for chunk in chunks:
                if len(chunk) == 0:
                    continue
                _check(path, kind, chunk, last, (width, height))
                last = int(chunk["t"][-1])
                packet = faery_packet(chunk)
                if kind == "evt3":
                    encoder.write({"events": packet})
                elif kind == "dat":
                    encoder.write(packet.astype(_DAT_DTYPE, casting="unsafe"))  # 'on' as DAT's 0/1 payload
                else:
                    packet["y"] = height - 1 - packet["y"]
                    encoder.write(packet)
                written += len(chunk)
    except RuntimeError as err:  # faery reports I/O errors as "... (os error N)"
        raise encoder_error(err, path, name) from None
    return written


def _check(path, kind: str, chunk: np.ndarray, last: int | None, size: tuple[int, int]) -> None:
    """Refuse, in one line, a chunk the format cannot hold or faery's encoder must not be given."""
    name, t = NAMES[kind], chunk["t"]
    if last is None and t[0] < 0:
        raise DataError(located(path, None, f"{name} stores times >= 0 µs, got {int(t[0])}"))
    steps = np.diff(t, prepend=t[0] if last is None else last)
    if steps.min() < 0:
        k = int(np.argmin(steps))
        raise DataError(located(path, None, f"events must be sorted by time; {int(t[k])} µs comes after "
                                            f"{int(t[k]) - int(steps[k])} µs"))
    if kind == "dat" and steps.max() >= DAT_MAX_GAP_US:
        k = int(np.argmax(steps))
        raise DataError(located(path, None, f"DAT stores 32-bit times: consecutive events must be less than "
                                            f"{DAT_MAX_GAP_US} µs (35.8 min) apart, got {int(steps[k])} µs "
                                            f"before {int(t[k])} µs"))
    if kind == "es" and t[-1] >= ES_MAX_TIME_US:
        raise DataError(located(path, None, f"Event Stream stores times from 0 as increments (a byte per 127 µs): "
                                            f"times must be below {ES_MAX_TIME_US} µs (71.6 min), got "
                                            f"{int(t[-1])} µs (.raw and .dat keep any start)"))
    width, height = size
    if int(chunk["x"].max()) >= width or int(chunk["y"].max()) >= height:
        k = int(np.argmax((chunk["x"] >= width) | (chunk["y"] >= height)))
        raise DataError(located(path, None, f"event at x={int(chunk['x'][k])}, y={int(chunk['y'][k])} is outside "
                                            f"the {width}x{height} sensor (--sensor-size sets it)"))
