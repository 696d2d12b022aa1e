"""A plan's parameter grid: the options of ``tofnet run`` it sweeps, each value checked on every network.

The size of the grid is bounded before it is expanded (``tofnet.batch.bounds``).
"""

from __future__ import annotations

from typing import Any, Mapping

from tofnet.errors import TofnetError, quote


#: Grid keys that are backend options (``tofnet run --workers``), not network parameters.
BACKEND_KEYS = ("workers",)


def grid_options() -> dict[str, str]:
    """Grid keys: the ``tofnet run`` options ``tofnet.api.apply_overrides`` knows, with - or _, and the
    backend's ``workers`` (besides ``PROCESS.PARAM``, one process's parameter, as ``tofnet run --set``)."""
    from tofnet.api import OVERRIDES
    keys = [*OVERRIDES, *BACKEND_KEYS]
    return {**{k.replace("_", "-"): k for k in keys}, **{k: k for k in keys}}


def _check_workers(value) -> None:
    if value != "auto" and (isinstance(value, bool) or not isinstance(value, int) or value < 0):
        raise TofnetError("expected a whole number of workers (0 or auto: one per CPU)")


def read_grid(self, tree: Mapping) -> dict[str, list[Any]]:
    """The plan's ``grid``: option -> its values, in plan order (``self``: the plan reader)."""
    section = tree.get("grid", {})
    if section is None:
        section = {}
    if not isinstance(section, Mapping):
        raise self.fail(tree, "grid", "grid", "expected a mapping option: [values]")
    options = grid_options()
    out: dict[str, list[Any]] = {}
    for key, values in section.items():
        path = f"grid.{key}"
        dotted = isinstance(key, str) and "." in key  # a process's parameter: checked on every network below
        if key not in options and not dotted:
            known = ", ".join(sorted(set(options.values())))
            raise self.fail(section, key, path, f"unknown option; expected one of {known}, or PROCESS.PARAM")
        option = key if dotted else options[key]
        if option in out:
            raise self.fail(section, key, path, f"{option} is given twice")
        values = values if isinstance(values, list) else [values]
        if not values:
            raise self.fail(section, key, path, "expected at least one value")
        seen: set[str] = set()
        for value in values:
            if repr(value) in seen:  # quoted alone: the list may be long
                raise self.fail(section, key, path, f"the value {quote(value)} is repeated")
            seen.add(repr(value))
        out[option] = list(values)
    return out

def _refuse_file_parameter(network, option: str) -> None:
    """A grid sweeps values, not files: a ``PROCESS.PARAM`` that names a file a process reads is refused (a
    plan from someone else would point a process at a file of the user's)."""
    process, dot, param = option.partition(".")
    if dot and any(p.name == param and p.reads_file for p in network.process(process).all_params()):
        raise TofnetError(f"{option} names a file a process reads; a grid sweeps values, not files: name it in "
                          f"a spec")


def _refuse_twice(network, grid: dict) -> None:
    """An option of ``tofnet run`` and a ``PROCESS.PARAM`` that set the same parameter of ``network``."""
    from tofnet.api import OVERRIDES, override_targets
    for option in grid:
        if option not in OVERRIDES:
            continue
        try:
            param, targets = override_targets(network, option)
        except TofnetError:
            continue  # a network without the option's process: applying the values says so
        for process in targets:
            if f"{process.name}.{param}" in grid:
                raise TofnetError(f"{process.name}.{param} is given twice (as {option} too)")


def check_grid(self, plan) -> None:
    """Apply every grid value, then every grid point, to every network (sized 240x180).

    ``self`` is the plan reader (its ``fail`` and ``tree``); errors quote a value, not a list.
    """
    from tofnet.api import apply_overrides, load_network
    section = self.tree.get("grid") or {}
    keys = {grid_options().get(k, k): k for k in section}
    for network in plan.networks:
        def fresh():
            return load_network(network.spec, sensor_size=None if network.spec else (240, 180),
                                estimator=network.estimator, allow_import=network.allow_import)[0]
        try:
            _refuse_twice(fresh(), plan.grid)
        except TofnetError as err:
            raise self.fail(self.tree, "grid", "grid", f"for network {network.name!r}: {err}") from None
        for option, values in plan.grid.items():
            for j, value in enumerate(values):
                try:
                    if option in BACKEND_KEYS:
                        _check_workers(value)
                        continue
                    target = fresh()
                    _refuse_file_parameter(target, option)
                    apply_overrides(target, **{option: value})
                except TofnetError as err:
                    raise self.fail(section[keys[option]], j, f"grid.{keys[option]}[{j}]",
                                    f"{quote(value)} for network {network.name!r}: {err}") from None
        if len(plan.grid) > 1:
            for point in plan.combinations():
                try:
                    apply_overrides(fresh(), **{k: v for k, v in point.items() if k not in BACKEND_KEYS})
                except TofnetError as err:
                    raise self.fail(self.tree, "grid", "grid", f"the point {quote(point, 120)} for network "
                                    f"{network.name!r}: {err}") from None
