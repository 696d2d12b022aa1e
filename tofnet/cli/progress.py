"""Progress on stderr for long runs: a live line on a terminal, a few lines in a log."""

from __future__ import annotations

import sys
import time


class Progress:
    """``Progress(label)(done, total)``; quiet for runs shorter than ``delay`` seconds."""

    def __init__(self, label: str, unit: str = "events", delay: float = 1.0, stream=None):
        self.label, self.unit, self.delay = label, unit, delay
        self.stream = stream or sys.stderr
        self.started = time.perf_counter()
        self.last_print = 0.0
        self.printed = False
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def __call__(self, done: int, total: int | None) -> None:
        now = time.perf_counter() - self.started
        interval = 0.2 if self.tty else 10.0
        if now < self.delay or now - self.last_print < interval:
            return
        self.last_print = now
        if total is None:  # a reader that cannot know the total in advance
            line = f"{self.label}: {_si(done)} {self.unit}  {now:5.1f} s elapsed"
        else:
            share = done / total if total else 1.0
            eta = now / share - now if share > 0 else float("nan")
            line = (f"{self.label}: {share:6.1%}  {_si(done)}/{_si(total)} {self.unit}  "
                    f"{now:5.1f} s elapsed, ~{eta:4.0f} s left")
        self.stream.write(("\r" + line) if self.tty else line + "\n")
        self.stream.flush()
        self.printed = True

    def done(self) -> None:
        if self.printed and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _si(n: int) -> str:
    for factor, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if n >= factor:
            return f"{n / factor:.1f}{suffix}"
    return str(n)
