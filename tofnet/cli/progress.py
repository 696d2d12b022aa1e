"""Progress on stderr for long runs: a live line on a terminal, a few lines in a log; and notes
(tofnet's log, e.g. "compiling kernels") on stderr between them."""

from __future__ import annotations

import logging
import sys
import time
from contextlib import contextmanager
from typing import Iterator

#: True while a terminal's live progress line has no newline yet (a note must start a new line).
_open_line = [False]


def note(text: str, stream=None) -> None:
    """One line on stderr (or ``stream``), below a live progress line if one is showing."""
    stream = stream or sys.stderr
    stream.write(("\n" if _open_line[0] else "") + text + "\n")
    stream.flush()
    _open_line[0] = False


class _NoteHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        note(self.format(record))


@contextmanager
def log_to_stderr(command: str) -> Iterator[None]:
    """While a command runs, show tofnet's log (INFO and up: e.g. the first compile of kernels) as
    notes on stderr, never on stdout, where some commands write data: ``tofnet COMMAND: message``.
    The logger is as it was afterwards (a script calling ``main`` and then the API sees no prefix)."""
    logger = logging.getLogger("tofnet")
    before = logger.level, logger.propagate
    handler = _NoteHandler()
    handler.setFormatter(logging.Formatter(f"tofnet {command}: %(message)s"))
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(before[0])
        logger.propagate = before[1]


class Progress:
    """``Progress(label)(done, total)``; quiet for runs shorter than ``delay`` seconds."""

    def __init__(self, label: str, unit: str = "events", delay: float = 1.0, stream=None):
        self.label, self.unit, self.delay = label, unit, delay
        self.stream = stream or sys.stderr
        self.started = time.perf_counter()
        self.compiled0 = _compile_seconds()
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
            working = now - (_compile_seconds() - self.compiled0)  # compiling kernels is not the pace of the run
            eta = working / share - working if share > 0 else float("nan")
            line = (f"{self.label}: {share:6.1%}  {_si(done)}/{_si(total)} {self.unit}  "
                    f"{now:5.1f} s elapsed, ~{eta:4.0f} s left")
        self.stream.write(("\r" + line) if self.tty else line + "\n")
        self.stream.flush()
        self.printed = True
        _open_line[0] = self.tty and self.stream is sys.stderr

    def done(self) -> None:
        if self.printed and self.tty and _open_line[0]:
            self.stream.write("\n")
            self.stream.flush()
        _open_line[0] = False


def _compile_seconds() -> float:
    """Seconds this process spent compiling kernels so far (0 before any kernel was imported)."""
    if "tofnet.kernels.compilation" not in sys.modules:  # importing it imports numba: not for that
        return 0.0
    return sys.modules["tofnet.kernels.compilation"].compile_seconds()


def _si(n: int) -> str:
    for factor, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if n >= factor:
            return f"{n / factor:.1f}{suffix}"
    return str(n)
