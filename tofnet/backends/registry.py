"""Backends by name. Built-ins are listed here; others register or use an entry point.

A new backend is one module with a ``Backend`` subclass plus either a call to
``register_backend`` or an entry point in the ``tofnet.backends`` group naming it.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Callable

from tofnet.backends.base import Backend
from tofnet.errors import BackendError

# name -> "module:attribute"; imported on first use so that numba compiles only what runs.
_BUILTIN = {
    "reference": "tofnet.backends.reference:ReferenceBackend",
    "float": "tofnet.backends.event_driven:FloatBackend",
    "fixed": "tofnet.backends.event_driven:FixedBackend",
    "multiproc": "tofnet.backends.multiproc:MultiprocBackend",
}
#: Built-ins that need an optional install (``tofnet[lava]``, Python 3.10): asked for by name,
#: not listed by ``available_backends`` (every backend listed there runs in any tofnet install).
_OPTIONAL = {
    "lava": "tofnet.backends.lava_backend:LavaBackend",
}
_registered: dict[str, Callable[[], Backend]] = {}


def register_backend(name: str, factory: Callable[..., Backend] | str) -> None:
    """Make a backend available as ``name``; ``factory`` (a callable or ``"module:attr"``)
    is called with the backend's options as keywords."""
    _registered[name] = factory if callable(factory) else _lazy(factory)


def _lazy(target: str) -> Callable[..., Backend]:
    def load(**options) -> Backend:
        module, _, attr = target.partition(":")
        try:
            factory = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError, ValueError) as err:  # ValueError: an empty module name
            raise BackendError(f"cannot load backend {target!r}: {type(err).__name__}: {err}") from err
        return factory(**options)
    return load


def _entry_point(name: str) -> Callable[..., Backend] | None:
    """The factory of the ``tofnet.backends`` entry point ``name``; one line when it does not load
    (a broken plug-in names itself, and leaves the other backends usable)."""
    for ep in entry_points(group="tofnet.backends"):
        if ep.name == name:
            try:
                return ep.load()
            except Exception as err:
                raise BackendError(f"entry point tofnet.backends:{name} ({ep.value}) failed to load: "
                                   f"{type(err).__name__}: {err}") from err  # the cause keeps its traceback
    return None


def available_backends(optional: bool = False) -> list[str]:
    """Names of every backend that can be asked for (``optional``: with those needing an optional install)."""
    names = dict.fromkeys(list(_BUILTIN) + (list(_OPTIONAL) if optional else []) + list(_registered))
    for ep in entry_points(group="tofnet.backends"):
        names.setdefault(ep.name)
    return list(names)


def get_backend(name: str, **options) -> Backend:
    """The backend called ``name``, built with ``options`` (e.g. ``workers=4``); raises naming
    the available ones, or the options the backend does not take."""
    if name in _registered:
        factory = _registered[name]
    elif name in _BUILTIN or name in _OPTIONAL:
        factory = _lazy({**_OPTIONAL, **_BUILTIN}[name])
    else:
        factory = _entry_point(name)
    if factory is not None:
        try:
            return factory(**options)
        except TypeError as err:
            if not options:
                raise
            raise BackendError(f"backend {name!r} does not take the options {sorted(options)}: {err}") from None
    raise BackendError(f"unknown backend {name!r}; available: {', '.join(available_backends(optional=True))}")


def backends_by_family() -> dict[str, list[str]]:
    """The built-in backends of each model family (for error messages)."""
    out: dict[str, list[str]] = {}
    for name, target in _BUILTIN.items():
        module, attr = target.split(":")
        family = getattr(getattr(importlib.import_module(module), attr), "family", None)
        if family:
            out.setdefault(family, []).append(name)
    return out
