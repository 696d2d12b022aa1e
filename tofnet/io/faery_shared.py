"""What tofnet's writers through faery share: events as faery's packets, faery's errors as Python's.

Used by ``tofnet.io.aedat`` (AEDAT4) and ``tofnet.io.prophesee_write`` (EVT3, DAT, Event Stream).
"""

from __future__ import annotations

import numpy as np

from tofnet.errors import DataError, located, quote, reason


def faery_packet(chunk: np.ndarray) -> np.ndarray:
    """``EVENT_DTYPE`` events as ``faery.EVENTS_DTYPE`` (``t`` µs as uint64, ``x``, ``y`` pixels, ``on`` for
    ``p == 1``); times must be >= 0 (the caller checks)."""
    import faery

    packet = np.empty(len(chunk), dtype=faery.EVENTS_DTYPE)
    packet["t"], packet["x"], packet["y"], packet["on"] = chunk["t"], chunk["x"], chunk["y"], chunk["p"] == 1
    return packet


def encoder_error(err: RuntimeError, path, what: str) -> Exception:
    """The ``OSError`` behind a faery encoder's ``RuntimeError`` ("... (os error N)": a full disk), else a
    one-line ``DataError`` naming ``path`` and the encoder (``what``, e.g. "AEDAT4")."""
    import os
    import re

    found = re.search(r"\(os error (\d+)\)", str(err))
    if found:
        code = int(found.group(1))
        return OSError(code, os.strerror(code))
    return DataError(located(path, None, f"the {what} encoder failed: {quote(reason(err), 80)}"))
