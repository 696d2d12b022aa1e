"""The one rule every output obeys: never replace a file the command reads, never a folder
tofnet did not write.

A command collects the files it reads: ``reading()`` opens a scope (the CLI opens one per
command, a batch worker one per task) in which every file opened through
``tofnet.io.files.open_regular`` is noted, and readers whose libraries open files
themselves (h5py, faery, rosbags) note them with ``note_read``. ``input_among`` tells
whether an output names one of them or one of the inputs a command lists before it
reads anything: same resolved path or same file (``st_dev`` and ``st_ino``, so hard
links and symlinks count). The writers of ``tofnet.io.files`` ask it once more just
before they rename a finished file into place, so a file read after the early checks
is protected too.

A folder output (an ECD recording, ``export --maps``, a batch's output) is marked with
``MANIFEST``, which lists what tofnet wrote there. Such a folder is replaced only when
it is empty or holds no file, at any depth, but what its manifest lists (``foreign_entries``).
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import re
from pathlib import Path
from typing import Iterable, Iterator

#: The file that marks a folder as tofnet's and lists what tofnet wrote in it.
MANIFEST = ".tofnet-manifest.json"

_READS: contextvars.ContextVar[dict | None] = contextvars.ContextVar("tofnet_reads", default=None)


@contextlib.contextmanager
def reading() -> Iterator[None]:
    """A scope in which the files read are collected (one command, one batch task)."""
    token = _READS.set({})
    try:
        yield
    finally:
        _READS.reset(token)


def note_read(path: str | Path, fd: int | None = None) -> None:
    """Note that the current command reads ``path`` (``fd``: its open descriptor). Outside
    a ``reading()`` scope this does nothing."""
    reads = _READS.get()
    if reads is None:
        return
    try:
        st = os.fstat(fd) if fd is not None else os.stat(path)
    except (OSError, ValueError):
        return
    reads[(st.st_dev, st.st_ino)] = Path(path)


def files_read() -> list[Path]:
    """The files noted so far in the current scope (empty outside one)."""
    reads = _READS.get()
    return list(reads.values()) if reads else []


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def input_among(path: str | Path, inputs: Iterable[str | Path] = ()) -> Path | None:
    """The input (of ``inputs`` or of the files read in this scope) that ``path`` would
    overwrite: same resolved path, or the same file through a hard link or symlink."""
    path = Path(path)
    if "\x00" in str(path):
        return None
    target, resolved = _identity(path), path.resolve()
    reads = _READS.get() or {}
    if target is not None and target in reads:
        return reads[target]
    for source in inputs:
        source = Path(source)
        if "\x00" in str(source):
            continue  # such a name cannot exist
        if source.resolve() == resolved or (target is not None and _identity(source) == target):
            return source
    return None


def inputs_under(folder: str | Path, inputs: Iterable[str | Path] = ()) -> Path | None:
    """An input (listed or read) that lies inside ``folder``, which an output would replace."""
    root = Path(folder).resolve()
    for source in [*inputs, *files_read()]:
        if "\x00" not in str(source) and Path(source).exists() and Path(source).resolve().is_relative_to(root):
            return Path(source)
    return None


def read_manifest(folder: str | Path) -> dict | None:
    """The manifest of ``folder`` (``{"written_by": ..., "files": [...]}``), or ``None``."""
    from tofnet.errors import DataError
    from tofnet.io.jsontext import parse_json
    try:
        with open(Path(folder) / MANIFEST, encoding="utf-8") as handle:
            data = parse_json(handle.read(), Path(folder) / MANIFEST)
    except (OSError, ValueError, DataError):  # unreadable: no manifest, so nothing in the folder is tofnet's
        return None
    if not isinstance(data, dict) or not isinstance(data.get("files"), list):
        return None
    return data


def foreign_entries(folder: str | Path) -> list[str]:
    """Files in ``folder`` that tofnet did not write there, as paths relative to it: every
    top-level name when it has no manifest, else every file, at any depth, whose relative
    path the manifest does not list. A listed folder (a batch lists its ``tasks`` and its
    scenario cache, which its workers fill as they run) covers what is under it; tofnet's
    own interrupted temporaries (``_temporary_of``) count as its own; empty folders hold
    nothing to lose."""
    folder = Path(folder)
    try:
        names = sorted(entry.name for entry in os.scandir(folder))
    except OSError as err:  # a folder that cannot be listed may hold anything: never tofnet's
        return [f"(a folder that cannot be listed: {err.strerror or type(err).__name__})"]
    manifest = read_manifest(folder)
    if manifest is None:
        return names
    listed = {MANIFEST, *(str(name) for name in manifest["files"])}
    found: list[str] = []
    _foreign_under(folder, "", listed, found)
    return found


#: A temporary name tofnet's writers make (``tempfile`` with prefix ``.NAME.`` and suffix
#: ``.part``, ``.old.part`` for a folder moved aside): eight characters of its alphabet between.
_TEMPORARY = re.compile(r"\.(?P<name>.+)\.[a-z0-9_]{8}(?:\.old)?\.part")


def _temporary_of(name: str, prefix: str, listed: set[str]) -> bool:
    """Whether ``name`` is tofnet's temporary for a file it lists at ``prefix`` (a user's
    ``.thesis.part`` is not: nothing called ``thesis`` is listed, nor has it the random part)."""
    match = _TEMPORARY.fullmatch(name)
    return match is not None and prefix + match["name"] in listed


def _foreign_under(folder: Path, prefix: str, listed: set[str], found: list[str]) -> None:
    try:
        entries = sorted(os.scandir(folder), key=lambda entry: entry.name)
    except OSError as err:
        found.append(f"{prefix}(a folder that cannot be listed: {err.strerror or type(err).__name__})")
        return
    for entry in entries:
        relative = prefix + entry.name
        if relative in listed or _temporary_of(entry.name, prefix, listed):
            continue
        # a symbolic link is never followed: tofnet writes none, so it is foreign (removing it would lose the link)
        if entry.is_dir(follow_symlinks=False):
            _foreign_under(Path(entry.path), relative + "/", listed, found)
        else:
            found.append(relative)
