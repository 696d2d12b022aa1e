"""Errors tofnet raises for bad input; the CLI prints them as one line each."""

from __future__ import annotations

import contextlib
import contextvars
from typing import Iterator


class TofnetError(Exception):
    """Base of every error caused by the user's network, spec or data."""


class NetworkError(TofnetError):
    """A process graph that cannot run: bad connection, shape, cycle, name."""


class SpecError(TofnetError):
    """A YAML network spec that does not describe a valid network."""


class DataError(TofnetError):
    """A recording or data file that cannot be read as expected."""


class BudgetError(TofnetError):
    """A network that does not fit the neuromorphic resource budget."""


class BackendError(TofnetError):
    """A backend that cannot run the network, or failed while running it."""


class UnsupportedError(BackendError):
    """A backend that cannot hold a kind of process the network has (e.g. a host-side estimator in
    Lava): the network does not apply to it, which the conformance suite reports as such."""


def located(path: object, line: int | None, message: str) -> str:
    """Format ``path:line: message`` (line omitted when unknown; an absurdly long path is
    shortened in the middle so that the message stays one readable line)."""
    text = shown_path(path)
    where = f"{text}:{line}" if line is not None else text
    return f"{where}: {message}"


def shown_path(path: object) -> str:
    """``path`` for a one-line message: escaped when not printable (a newline in a file name must not
    break the line), shortened in the middle beyond 240 characters."""
    text = str(path)
    if not text.isprintable():
        text = text.encode("unicode_escape", "backslashreplace").decode("ascii")
    return text if len(text) <= 240 else f"{text[:100]}...{text[-100:]}"


def quote(value: object, limit: int = 40) -> str:
    """``repr(value)`` cut to ``limit`` characters: error messages never echo more of a
    user's file than the offending field, and never a whole binary blob."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def quote_field(path: object, field: object) -> str:
    """A field of the file ``path`` for an error message: ``quote(field)``, unless ``field_hidden(path)``."""
    return field_hidden(path) or quote(field)


def field_hidden(path: object) -> str | None:
    """Why no field of the file ``path`` may be quoted (the words that stand for it), or ``None``: a symlink
    takes the file, or one of the two folders it is in, out of the folder its name is in (a recording's
    ``calib.txt`` linked to ``~/.git-credentials``, its ``disparity/`` linked to ``~/secrets/``), so what it
    holds is not the recording's to show. Links higher up (``/home`` on a cluster) are not looked at.
    Within ``fields_shown_within(folder)`` a file outside ``folder`` (links resolved) is not quoted either."""
    import os
    try:
        name = os.path.abspath(os.fspath(path))
        linked = next((link for link in (name, os.path.dirname(name), os.path.dirname(os.path.dirname(name)))
                       if os.path.islink(link) and not _inside(os.path.realpath(link),
                                                               os.path.realpath(os.path.dirname(link)))), None)
        scope = _SHOWN_WITHIN.get()
        outside = scope is not None and not _inside(os.path.realpath(name), scope[0])
    except (TypeError, ValueError, OSError):
        linked = os.fspath(path) if isinstance(path, (str, os.PathLike)) else str(path)
        outside = False
    if linked is not None:
        return (f"a field not shown ({shown_path(linked)} links out of its folder, to "
                f"{shown_path(os.path.realpath(linked))})")
    if outside:
        return f"a field not shown ({shown_path(path)} is outside {scope[1]})"
    return None


#: The folder whose files' fields may be quoted, and what it is, in a ``fields_shown_within`` scope.
_SHOWN_WITHIN: contextvars.ContextVar[tuple[str, str] | None] = contextvars.ContextVar("tofnet_shown_within",
                                                                                      default=None)


@contextlib.contextmanager
def fields_shown_within(folder: object, what: str) -> Iterator[None]:
    """A scope in which ``quote_field`` quotes only files inside ``folder`` (``what``, e.g. "the plan's
    folder"): a batch plan may name a file anywhere by an absolute path, and its errors go to the terminal
    and to results.csv, where the first field of ``/home/me/.env`` read as events must not appear."""
    import os
    token = _SHOWN_WITHIN.set((os.path.realpath(os.fspath(folder)), what))
    try:
        yield
    finally:
        _SHOWN_WITHIN.reset(token)


def _inside(path: str, folder: str) -> bool:
    import os
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def interrupted(err: BaseException) -> bool:
    """Whether a ``KeyboardInterrupt`` is among the exceptions that led to ``err`` (Ctrl-C inside a compiled
    kernel: numba's dispatcher wraps it in a ``SystemError``)."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def reason(err: BaseException, limit: int = 80) -> str:
    """The first line of an exception's text, cut to ``limit`` characters: library
    messages may quote raw bytes of the file (zipfile quotes whole headers)."""
    lines = str(err).splitlines()
    text = lines[0] if lines else type(err).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."
