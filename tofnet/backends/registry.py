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
    def resolve() -> Callable[..., Backend]:
        module, _, attr = target.partition(":")
        try:
            return getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError, ValueError) as err:  # ValueError: an empty module name
            raise BackendError(f"cannot load backend {target!r}: {type(err).__name__}: {err}") from err

    def load(**options) -> Backend:
        return resolve()(**options)
    load.resolve = resolve  # the class itself, for its options' names
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
    factory = _factory(name)
    if factory is None:
        raise BackendError(f"unknown backend {name!r}; available: {', '.join(available_backends(optional=True))}")
    return _build(name, factory, options)


def check_backend_options(name: str, options: dict) -> None:
    """Raise ``BackendError`` when the backend ``name`` does not take ``options`` (by its signature) or, for the
    built-ins that run anywhere, refuses their values (one is built and dropped). A backend that is unknown or
    cannot be built here is left to ``get_backend`` where it runs: a spec naming ``lava`` still runs with
    ``--backend fixed`` where lava is not installed."""
    if not options:
        return
    try:
        factory = _factory(name)
        taken = None if factory is None else _option_names(factory)
    except BackendError:
        return
    unknown = [key for key in options if taken is not None and key not in taken]
    if unknown:
        raise BackendError(_unknown_options(name, unknown, taken))
    if name in _BUILTIN and name not in _registered:
        _build(name, factory, options)


def _factory(name: str) -> Callable[..., Backend] | None:
    if name in _registered:
        return _registered[name]
    if name in _BUILTIN or name in _OPTIONAL:
        return _lazy({**_OPTIONAL, **_BUILTIN}[name])
    return _entry_point(name)


def _build(name: str, factory: Callable[..., Backend], options: dict) -> Backend:
    try:
        return factory(**options)
    except TypeError as err:
        if not options:
            raise
        taken = _option_names(factory)
        unknown = [key for key in options if taken is not None and key not in taken]
        if unknown:
            raise BackendError(_unknown_options(name, unknown, taken)) from None
        raise BackendError(f"backend {name!r} does not take the options {sorted(options)}: {err}") from None


def _unknown_options(name: str, unknown: list[str], taken: list[str]) -> str:
    return (f"backend {name!r} does not take the option{'s' if len(unknown) > 1 else ''} "
            f"{', '.join(map(repr, unknown))}; its options: {', '.join(taken) or 'none'}")


def _option_names(factory: Callable[..., Backend]) -> list[str] | None:
    """The keywords ``factory`` takes (None when it takes any, or cannot tell)."""
    import inspect
    try:
        target = factory.resolve() if hasattr(factory, "resolve") else factory
        parameters = list(inspect.signature(target).parameters.values())
    except (TypeError, ValueError, BackendError):
        return None
    if any(p.kind is p.VAR_KEYWORD for p in parameters):
        return None
    return [p.name for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]


def backends_by_family() -> dict[str, list[str]]:
    """The built-in backends of each model family (for error messages)."""
    out: dict[str, list[str]] = {}
    for name, target in _BUILTIN.items():
        module, attr = target.split(":")
        family = getattr(getattr(importlib.import_module(module), attr), "family", None)
        if family:
            out.setdefault(family, []).append(name)
    return out
