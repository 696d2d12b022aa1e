"""Whether an Event Stream (``.es``) file ends inside an event (a copy or a recording cut short).

Event Stream 2.x, as faery writes and reads it, encodes a DVS or ATIS event in five bytes (the time
since the previous event and the polarity, then ``x`` and ``y`` as little-endian 16-bit words), between
which one-byte overflows and resets may stand (a first byte of at least 0xFE for DVS, 0xFC for ATIS).
faery's decoder stops silently at an incomplete last event; this walks the same byte state machine over
the file, in chunks, so the reader can say how many bytes it could not read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numba import njit

import tofnet.numba_cache  # noqa: F401 - before any cached kernel: numba picks its cache key at decoration

#: Bytes of the 2.x header before the events: signature (12), version (3), type (1), width (2), height (2).
HEADER_BYTES = 20
#: Bytes of one DVS or ATIS event.
EVENT_BYTES = 5
_CHUNK = 1 << 24


@njit(cache=True)
def walk_bytes(data, state, not_an_event):
    """Run the event byte state machine (0: between events, 1 to 4: inside one) over ``data``; the new state."""
    for i in range(data.shape[0]):
        if state == 0:
            state = 0 if data[i] >= not_an_event else 1
        else:
            state = (state + 1) % EVENT_BYTES
    return state


def partial_event_bytes(path: str | Path, event_type: str) -> int:
    """Bytes at the end of a DVS or ATIS Event Stream file that begin an event it does not finish (0 to 4)."""
    not_an_event = 0xFE if event_type == "dvs" else 0xFC
    state = 0
    with open(path, "rb") as handle:
        handle.seek(HEADER_BYTES)
        while True:
            chunk = np.fromfile(handle, np.uint8, count=_CHUNK)
            if chunk.size == 0:
                return state
            state = walk_bytes(chunk, state, not_an_event)
