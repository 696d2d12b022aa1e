"""The Process base class: a declaration of ports and parameters, no execution code."""

from __future__ import annotations

import os
import re
import sys
from typing import Any, ClassVar

from tofnet.core.counters import Count
from tofnet.core.params import Param
from tofnet.core.ports import InPort, OutPort, PortSpec
from tofnet.core.vars import Var
from tofnet.errors import NetworkError

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

SENSOR_SIZE = Param("sensor_size", "size", None, unit="px",
                    doc="sensor (width, height); taken from the upstream process when omitted", optional=True)


class Process:
    """A node of a tofnet network.

    Subclasses declare ``inports``, ``outports`` and ``params`` as class attributes and
    ``resources_per_pixel`` (what one pixel of the process needs on a neuromorphic
    core; empty for processes that run on the host). Backends implement them.
    """

    inports: ClassVar[tuple[PortSpec, ...]] = ()
    outports: ClassVar[tuple[PortSpec, ...]] = ()
    params: ClassVar[tuple[Param, ...]] = ()
    #: State variables a session can read (and some set) between runs (Lava's ``Var``).
    vars: ClassVar[tuple[Var, ...]] = ()
    #: Per-pixel needs on a neuromorphic core, e.g. ``{"accumulators": 8, "neurons": 4}``.
    resources_per_pixel: ClassVar[dict[str, int]] = {}
    #: What the process counts (``Count``: events read, accepted, dropped and rejected by reason,
    #: outputs); its models' ``counts()`` return these keys. Results and reports add them up from here.
    counters: ClassVar[tuple[Count, ...]] = ()
    #: Steps the process adds between what it receives (or reads) and what it sends on its output
    #: ports, beyond the one step of each connection: the default of every output port whose
    #: ``PortSpec.added_latency_steps`` is None (results give each output's latency from them).
    added_latency_steps: ClassVar[int] = 0
    #: ``"core"``: runs on neuromorphic cores; ``"host"``: runs off-chip (input, velocity).
    placement: ClassVar[str] = "core"

    _registry: ClassVar[dict[str, type["Process"]]] = {}
    #: Class name -> where each class of that name is defined -> its ``module:Class`` (two: a bare name is ambiguous).
    _defined: ClassVar[dict[str, dict[str, str]]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        clash = {s.name for s in cls.inports + cls.outports} & {p.name for p in cls.all_params()}
        if clash:
            raise TypeError(f"{cls.__name__}: {', '.join(sorted(clash))} is both a port and a parameter")
        for inputs, specs in ((True, cls.inports), (False, cls.outports)):
            for spec in specs:
                steps = spec.added_latency_steps
                if steps is not None and (inputs or isinstance(steps, bool) or not isinstance(steps, int) or steps < 0):
                    raise TypeError(f"{cls.__name__}.{spec.name}: added_latency_steps is declared on output ports, "
                                    f"as a whole number of steps >= 0 (or None), got {steps!r}")
        Process._registry[cls.__name__] = cls
        if "<locals>" not in cls.__qualname__:  # a class made inside a function no spec can name by module
            Process._defined.setdefault(cls.__name__, {})[_defined_where(cls)] = f"{cls.__module__}:{cls.__qualname__}"

    def __init__(self, name: str | None = None, **values: Any):
        type_name = type(self).__name__
        self.name = name if name is not None else _default_name(type_name)
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise NetworkError(f"{type_name}: name {self.name!r} must be an identifier (letters, digits, _)")
        self._values: dict[str, Any] = {}
        declared = {p.name: p for p in self.all_params()}
        unknown = sorted(set(values) - set(declared))
        if unknown:
            raise NetworkError(f"{self.name} ({type_name}): unknown parameter(s) {', '.join(unknown)}; "
                               f"expected {', '.join(declared)}")
        for param in declared.values():
            raw = values.get(param.name, param.default)
            self._values[param.name] = param.coerce(raw, self.name)
        self._check()
        self.ports: dict[str, InPort | OutPort] = {}
        for spec in self.inports:
            self.ports[spec.name] = InPort(self, spec)
        for spec in self.outports:
            self.ports[spec.name] = OutPort(self, spec)

    @classmethod
    def port_latency_steps(cls, port: str) -> int:
        """Steps the process adds before sending on output ``port``: the port's ``added_latency_steps``,
        else the process's."""
        for spec in cls.outports:
            if spec.name == port:
                return cls.added_latency_steps if spec.added_latency_steps is None else spec.added_latency_steps
        raise NetworkError(f"{cls.__name__} has no output port {port!r}; outputs: "
                           f"{', '.join(s.name for s in cls.outports) or 'none'}")

    @classmethod
    def all_params(cls) -> tuple[Param, ...]:
        """Every parameter, the shared ``sensor_size`` first."""
        own = tuple(p for p in cls.params if p.name != SENSOR_SIZE.name)
        return (SENSOR_SIZE,) + own if not any(p.name == SENSOR_SIZE.name for p in cls.params) else cls.params

    @classmethod
    def ambiguity(cls, type_name: str) -> str | None:
        """Why a bare class name cannot name one process type (two modules define it), or None."""
        where = sorted(cls._defined.get(type_name, {}).values())
        if len(where) < 2:
            return None
        return f"process type {type_name!r} is defined by {' and '.join(where)}; name one as module:Class"

    @classmethod
    def type_named(cls, type_name: str) -> type["Process"]:
        """The process class called ``type_name``; raises naming the known types, or the modules
        that define it when more than one does."""
        ambiguous = cls.ambiguity(type_name)
        if ambiguous:
            raise NetworkError(ambiguous)
        try:
            return cls._registry[type_name]
        except KeyError:
            known = ", ".join(sorted(cls._registry))
            raise NetworkError(f"unknown process type {type_name!r}; known types: {known}") from None

    def _check(self) -> None:
        """Cross-parameter checks; subclasses extend."""

    def __getattr__(self, item: str) -> Any:
        # Ports and parameters read as attributes: proc.events, proc.distance.
        if item.startswith("_") or item in ("ports",):
            raise AttributeError(item)
        ports = self.__dict__.get("ports", {})
        if item in ports:
            return ports[item]
        values = self.__dict__.get("_values", {})
        if item in values:
            return values[item]
        raise AttributeError(f"{type(self).__name__} {self.__dict__.get('name')!r} has no port or parameter {item!r}")

    @property
    def sensor_size(self) -> tuple[int, int] | None:
        return self._values["sensor_size"]

    @sensor_size.setter
    def sensor_size(self, size: tuple[int, int]) -> None:
        self._values["sensor_size"] = size

    @property
    def values(self) -> dict[str, Any]:
        """A copy of the parameter values (durations in s, lengths in m)."""
        return dict(self._values)

    @classmethod
    def var(cls, name: str) -> Var:
        """The declared variable ``name``; raises naming the ones there are."""
        for v in cls.vars:
            if v.name == name:
                return v
        known = ", ".join(v.name for v in cls.vars) or "none"
        raise NetworkError(f"{cls.__name__} has no variable {name!r}; variables: {known}")

    def receptive_offsets(self) -> list[tuple[int, int]]:
        """Offsets ``(du, dv)`` (px) of the input pixels one pixel of this process reads.

        The compiler derives each core's halo from these. Default: its own pixel.
        """
        return [(0, 0)]

    def field_layout(self, port: str) -> tuple[int, int]:
        """For an output port of ``field`` payload: ``(side, every)``, the side (px) of the squares
        that share one value and the steps between two updates. The compiler sizes the traffic
        of the port from it. Default: a value per pixel, every step."""
        return (1, 1)

    def compiler_notes(self) -> tuple[str, ...]:
        """What the compiler report says about this process's layer besides its resources (e.g. an
        operation the paper's Loihi 2 mapping avoided), one line each. Default: nothing."""
        return ()

    def set_param(self, name: str, value: Any) -> None:
        """Change one parameter, with the same conversion and checks as the constructor."""
        self.set_params({name: value})

    def set_params(self, values: dict[str, Any]) -> None:
        """Change several parameters together, all or none: each converted as the constructor does, then the
        cross-parameter checks once on them all, so parameters that depend on each other (a velocity's
        ``source`` and its ``samples``) may be given in any order."""
        declared = {p.name: p for p in self.all_params()}
        for name in values:
            if name not in declared:
                raise NetworkError(f"{self.name} ({type(self).__name__}) has no parameter {name!r}; "
                                   f"expected {', '.join(declared)}")
        previous = {name: self._values[name] for name in values}
        try:
            for name, value in values.items():
                self._values[name] = declared[name].coerce(value, self.name)
            self._check()
        except BaseException:
            self._values.update(previous)
            raise

    def port(self, name: str) -> InPort | OutPort:
        try:
            return self.ports[name]
        except KeyError:
            raise NetworkError(f"{self.name} ({type(self).__name__}) has no port {name!r}; "
                               f"ports: {', '.join(self.ports)}") from None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


def _default_name(type_name: str) -> str:
    """``TimeOfTravelProcess`` -> ``time_of_travel``."""
    base = re.sub(r"Process$", "", type_name)
    return re.sub(r"(?<!^)(?=[A-Z])", "_", base).lower() or "process"


def _defined_where(cls: type) -> str:
    """Where ``cls`` is defined: its module's file and its qualified name (a script run as ``__main__``
    and imported under its own name too defines one class, not two), or its module's name without a file."""
    path = getattr(sys.modules.get(cls.__module__), "__file__", None)
    return f"{os.path.realpath(path) if path else cls.__module__}:{cls.__qualname__}"
