"""numba's disk cache of tofnet's kernels, kept valid when any of tofnet's sources changes.

numba keys a cached kernel on its own file only (mtime and size). A kernel that calls a
kernel of another file, or reads another module's constant (numba freezes globals when it
compiles), kept its old machine code when only that other file changed: an edit to
``time_surface_fit.py`` was silently ignored until ``time_surface.py`` changed too, and so
would a checkout that changes one helper file. Here every cached kernel of a file under a
registered root is keyed on the stamps of all the ``.py`` files under it as well, so any
change recompiles (20-60 s, once). Imported by every package or module that defines cached
kernels, before it defines them: numba picks a kernel's cache locator at decoration.

Where the cache lives: ``NUMBA_CACHE_DIR`` when set; beside the sources (``__pycache__``) in a
source checkout (a ``pyproject.toml`` beside the package); for an installed package, numba's
per-user cache folder (``~/.cache/numba`` on Linux), never the environment's ``site-packages``: ``pip
uninstall`` removes only the files it installed, and a package folder left holding cache files
is imported as an empty namespace package, shadowing a later install of the same name.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

from numba.core.caching import CacheImpl, InTreeCacheLocator, UserProvidedCacheLocator, UserWideCacheLocator

_ROOTS: list[str] = []


def register_root(root: str | Path) -> None:
    """Key the cached kernels of files under ``root`` on every ``.py`` file under it too (idempotent)."""
    root = os.path.realpath(root)
    if root not in _ROOTS:
        _ROOTS.append(root)
        _sources_stamp.cache_clear()
    if _InTree not in CacheImpl._locator_classes:  # before numba's own, in its order: the first that accepts wins
        CacheImpl._locator_classes[:0] = [_UserProvided, _InTree, _UserWide, _InTreeAtLast]


def _root_of(py_file: str) -> str | None:
    path = os.path.realpath(py_file)
    return next((root for root in _ROOTS if path.startswith(root + os.sep)), None)


@functools.lru_cache(maxsize=None)
def _sources_stamp(root: str) -> str:
    """A digest of the path, mtime (ns) and size of every ``.py`` file under ``root`` (about 1 ms for tofnet's)."""
    digest = hashlib.sha256()
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            st = os.stat(path)
            digest.update(f"{os.path.relpath(path, root)}\0{st.st_mtime_ns}\0{st.st_size}\n".encode())
    return digest.hexdigest()


class _WholeSourceStamp:
    """A locator for files under a registered root whose stamp also covers the root's other sources."""

    @classmethod
    def from_function(cls, py_func, py_file):
        if _root_of(py_file) is None:
            return None  # not ours: numba's own locators decide
        return super().from_function(py_func, py_file)

    def get_source_stamp(self):
        return super().get_source_stamp(), _sources_stamp(_root_of(self._py_file))


class _UserProvided(_WholeSourceStamp, UserProvidedCacheLocator):
    """``NUMBA_CACHE_DIR``, when it is set."""


def _is_checkout(root: str) -> bool:
    """Whether the package folder ``root`` is a source checkout's (its project file beside it), not an install."""
    return os.path.isfile(os.path.join(os.path.dirname(root), "pyproject.toml"))


class _InTree(_WholeSourceStamp, InTreeCacheLocator):
    """Beside the sources (``__pycache__``) of a source checkout, when numba may write there."""

    @classmethod
    def from_function(cls, py_func, py_file):
        root = _root_of(py_file)
        if root is not None and not _is_checkout(root):
            return None  # an install: the per-user folder (``_UserWide``)
        return super().from_function(py_func, py_file)


class _UserWide(_WholeSourceStamp, UserWideCacheLocator):
    """numba's per-user cache folder, for installed packages."""


class _InTreeAtLast(_WholeSourceStamp, InTreeCacheLocator):
    """Beside an installed package's sources, when the user has no writable cache folder (still stamped)."""


register_root(Path(__file__).resolve().parent)
