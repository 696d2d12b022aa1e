"""Work cut into pieces of about half a second each, so that a progress callback is called every so often
whatever the backend's speed (``tofnet.api``: a streamed run's chunks, a session's steps with monitors).

The first piece is small; each next one is sized from the pace of the one before, up to ``most`` (a fast
backend then takes each chunk whole, as before: one piece more per run, the first). Cutting the work does
not change what it computes: a stream takes packets cut anywhere, a session steps to any boundary.
"""

from __future__ import annotations

import time

#: Seconds of work a piece aims at: a progress line shows every 0.2 s on a terminal.
PIECE_SECONDS = 0.5


class Pacer:
    """``size(left)``: the next piece (units: events or steps); ``took(units)`` after it, which sizes the next."""

    def __init__(self, first: int, most: int, seconds: float | None = None):
        self.first, self.most = max(1, first), max(1, most)
        self.seconds = PIECE_SECONDS if seconds is None else seconds
        self.next = min(self.first, self.most)
        self._started = time.perf_counter()

    def size(self, left: int) -> int:
        self._started = time.perf_counter()
        return max(1, min(self.next, left))

    def took(self, units: int) -> None:
        spent = time.perf_counter() - self._started
        rate = units / spent if spent > 0 else float("inf")
        self.next = int(min(self.most, max(self.first, rate * self.seconds)))
