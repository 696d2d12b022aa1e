"""Which model runs a process on a backend: an explicit table, no directory scanning.

Every backend runs models of one family (``reference``, ``float`` or ``fixed``; see
``Backend.family``). The model of a process for a family is, in this order:
1. the model registered for the process's own class and that family (``register_model``
   or the ``@model`` decorator, usually next to the user's process declaration);
2. tofnet's built-in model for that class and family (the table below);
3. the same, for each base class of the process in method resolution order.
A process with no model for the family fails before anything runs, naming the process,
its type, the backend and the families (backends) that do have a model.
"""

from __future__ import annotations

import importlib
from typing import Callable, TypeVar

from tofnet.core.process import Process
from tofnet.errors import BackendError
from tofnet.models.base import FAMILIES, Model

M = TypeVar("M", bound=type[Model])

_ALL = FAMILIES
# (process class name, family) -> "module:attribute"; imported on first use so numba
# compiles only what runs.
_BUILTIN: dict[tuple[str, str], str] = {}
for _family in _ALL:
    _BUILTIN[("InputProcess", _family)] = "tofnet.models.input:InputModel"
    _BUILTIN[("VelocityProcess", _family)] = "tofnet.models.velocity:VelocityModel"
    _BUILTIN[("AngularVelocityProcess", _family)] = "tofnet.models.angular_velocity:AngularVelocityModel"
    _BUILTIN[("TimeSurfaceProcess", _family)] = "tofnet.models.time_surface:TimeSurfaceModel"
for _family, _suffix in (("reference", "StepModel"), ("float", "EventModel"), ("fixed", "EventModel")):
    _BUILTIN[("TimeOfTravelProcess", _family)] = f"tofnet.models.time_of_travel:TimeOfTravel{_suffix}"
    _BUILTIN[("DepthProcess", _family)] = f"tofnet.models.depth:Depth{_suffix}"
    _BUILTIN[("BackgroundActivityFilterProcess", _family)] = (
        f"tofnet.models.background_filter:BackgroundFilter{_suffix}")
    _BUILTIN[("UndistortProcess", _family)] = f"tofnet.models.undistort:Undistort{_suffix}"
_BUILTIN_MODULES = ("tofnet.processes",)  # where the built-in process classes live

_registered: dict[tuple[type, str], type[Model]] = {}


def register_model(process_type: type[Process], families: str | tuple[str, ...], model_class: type[Model]) -> None:
    """Run ``process_type`` with ``model_class`` on the backends of ``families``."""
    if not (isinstance(process_type, type) and issubclass(process_type, Process)):
        raise BackendError(f"register_model: expected a Process subclass, got {process_type!r}")
    if not (isinstance(model_class, type) and issubclass(model_class, Model)):
        raise BackendError(f"register_model: expected a Model subclass, got {model_class!r}")
    for family in (families,) if isinstance(families, str) else families:
        if family not in FAMILIES:
            raise BackendError(f"register_model: unknown family {family!r}; expected one of {', '.join(FAMILIES)}")
        _registered[(process_type, family)] = model_class


def model(process_type: type[Process], *families: str) -> Callable[[M], M]:
    """Class decorator: ``@model(MyProcess, "reference", "float", "fixed")`` (all three by default)."""
    def register(model_class: M) -> M:
        register_model(process_type, families or FAMILIES, model_class)
        return model_class
    return register


def _lookup(cls: type, family: str) -> type[Model] | None:
    if (cls, family) in _registered:
        return _registered[(cls, family)]
    target = _BUILTIN.get((cls.__name__, family))
    if target is not None and cls.__module__.startswith(_BUILTIN_MODULES):
        module, attribute = target.split(":")
        return getattr(importlib.import_module(module), attribute)
    return None


def families_of(process_type: type[Process]) -> list[str]:
    """The families that have a model for ``process_type`` (its own or a base class's)."""
    return [f for f in FAMILIES if any(_has(cls, f) for cls in process_type.__mro__ if _is_process(cls))]


def _has(cls: type, family: str) -> bool:
    return (cls, family) in _registered or ((cls.__name__, family) in _BUILTIN
                                            and cls.__module__.startswith(_BUILTIN_MODULES))


def _is_process(cls: type) -> bool:
    return isinstance(cls, type) and issubclass(cls, Process) and cls is not Process


def model_for(process: Process, family: str, backend: str,
              backends_by_family: Callable[[], dict[str, list[str]]] | None = None) -> type[Model]:
    """The model class that runs ``process`` on ``backend`` (of ``family``); raises when none does.

    ``backends_by_family()`` names the backends of each family, for the error message.
    """
    for cls in type(process).__mro__:
        if not _is_process(cls):
            continue
        found = _lookup(cls, family)
        if found is not None:
            return found
    have = families_of(type(process))
    names = backends_by_family() if backends_by_family is not None else {}
    where = [f"{f} ({', '.join(names[f])})" if names.get(f) else f for f in have]
    hint = (f"it has models for the families {', '.join(where)}" if have else
            "it has no model at all: register one with tofnet.models.register_model (docs/extending.md)")
    raise BackendError(f"process {process.name!r} ({type(process).__name__}) has no {family!r} model, "
                       f"which the {backend!r} backend runs; {hint}")
