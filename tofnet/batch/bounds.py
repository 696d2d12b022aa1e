"""Bounds on the work a plan can ask for before anything runs (docs/batch.md, "Limits").

A small plan must not be able to make ``tofnet batch --check`` run for minutes: the number
of tasks is computed from the sizes of the plan's lists before any grid is expanded, and
a glob looks at a bounded number of files and folders, never leaving the plan's folder
unless its pattern is absolute (nor does a path it reads, ``check_inside_plan``).
"""

from __future__ import annotations

import fnmatch
import math
import os
from pathlib import Path
from typing import Iterable

from tofnet.errors import TofnetError, quote

#: Most tasks (recordings x networks x grid points) a plan may expand to.
MAX_TASKS = 10_000
#: Most files and folders one glob of a plan may look at.
MAX_GLOB_ENTRIES = 100_000


def task_count(recordings: int, networks: int, grid_sizes: Iterable[int]) -> int:
    """Tasks of a plan, from the sizes of its lists (nothing expanded)."""
    return recordings * networks * math.prod(grid_sizes)


def check_task_count(recordings: int, networks: int, grid_sizes: Iterable[int]) -> None:
    """Raise (one line) when the plan would expand to more than ``MAX_TASKS`` tasks."""
    sizes = list(grid_sizes)
    count = task_count(recordings, networks, sizes)
    if count > MAX_TASKS:
        grid = " x ".join(map(str, sizes)) or "1"
        raise TofnetError(f"{recordings} recordings x {networks} networks x ({grid}) grid points = {count:,} tasks; "
                          f"a plan may have at most {MAX_TASKS:,}: split it")


def bounded_glob(pattern: str, base: Path, limit: int | None = None) -> list[Path]:
    """The sorted matches of ``pattern`` (``*``, ``?``, ``[...]``; ``**``: any folders below).

    A relative pattern is taken in ``base`` and may not climb out of it (``..``); ``**``
    does not follow symlinked folders; names starting with ``.`` match only a pattern
    part that starts with ``.``. Raises (one line) after looking at ``limit`` entries
    (default ``MAX_GLOB_ENTRIES``).
    """
    try:
        return _glob(pattern, base, MAX_GLOB_ENTRIES if limit is None else limit)
    except (OSError, ValueError) as err:  # a name too long, a NUL byte: nothing can match
        raise TofnetError(f"{quote(pattern)}: cannot be looked up ({getattr(err, 'strerror', None) or err})") \
            from None


def check_inside_plan(name: str, what: str = "path") -> None:
    """Refuse (one line) a relative ``name`` that climbs out of the plan's folder with ``..``: a plan from
    someone else could otherwise read ``../../.env`` beside it. An absolute name, which whoever runs the
    plan sees, may look anywhere (errors then quote no field of it, ``tofnet.errors.fields_shown_within``)."""
    path = Path(name).expanduser()
    if not path.is_absolute() and ".." in path.parts:
        raise TofnetError(f"{quote(name)} leaves the plan's folder (..); give an absolute {what} to look "
                          "elsewhere")


def _glob(pattern: str, base: Path, limit: int) -> list[Path]:
    check_inside_plan(pattern, "pattern")
    path = Path(pattern).expanduser()
    parts = path.parts[1:] if path.is_absolute() else path.parts
    root = Path(path.anchor) if path.is_absolute() else base
    fixed = 0
    while fixed < len(parts) and not _magic(parts[fixed]):
        fixed += 1
    start, rest = root.joinpath(*parts[:fixed]), parts[fixed:]
    if not rest:
        return [start] if start.exists() else []
    seen = [0]
    found: set[Path] = set()
    stack = [(start, 0)]
    while stack:
        folder, j = stack.pop()
        part, last = rest[j], j == len(rest) - 1
        if part == "**":  # this folder and everything below (last), or any folders before the rest
            if last:
                found.add(folder)
            else:
                stack.append((folder, j + 1))
            for entry in _entries(folder, seen, limit, pattern):
                if entry.name.startswith("."):
                    continue
                if entry.is_dir(follow_symlinks=False):
                    stack.append((Path(entry.path), j))
                elif last:
                    found.add(Path(entry.path))
        elif _magic(part):
            for entry in _entries(folder, seen, limit, pattern):
                if (part.startswith(".") or not entry.name.startswith(".")) and fnmatch.fnmatch(entry.name, part):
                    if last:
                        found.add(Path(entry.path))
                    elif entry.is_dir():
                        stack.append((Path(entry.path), j + 1))
        else:
            child = folder / part
            if last and (child.exists() or child.is_symlink()):
                found.add(child)
            elif not last and child.is_dir():
                stack.append((child, j + 1))
    return sorted(found)


def exists(path: Path, test=Path.exists) -> bool:
    """``test(path)``, False when the path cannot even be looked up (a name too long, a NUL)."""
    try:
        return test(path)
    except (OSError, ValueError):
        return False


def _magic(part: str) -> bool:
    return any(c in part for c in "*?[")


def _entries(folder: Path, seen: list[int], limit: int, pattern: str):
    try:
        with os.scandir(folder) as entries:
            for entry in entries:
                seen[0] += 1
                if seen[0] > limit:
                    raise TofnetError(f"{quote(pattern)} looks at more than {limit:,} files and folders; "
                                      "give a narrower pattern")
                yield entry
    except (PermissionError, NotADirectoryError, FileNotFoundError):
        return  # glob's behaviour: what cannot be listed matches nothing
