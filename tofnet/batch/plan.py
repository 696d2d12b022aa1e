"""Batch plans: which recordings, which networks, which parameter grid, what to keep.

``load_plan`` reads a YAML plan (docs/batch.md) and validates all of it before anything
runs: every path and glob must exist, every spec must load, every scenario must be a
built-in one, and every grid value must be accepted by every network. Errors name the
file, the line and the key, in one line.
"""

from __future__ import annotations

import glob as globbing
import itertools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from tofnet.batch.bounds import bounded_glob, check_inside_plan, check_task_count, exists
from tofnet.batch.grid import check_grid, read_grid
from tofnet.batch.reading import READ_KEYS
from tofnet.errors import SpecError, TofnetError, fields_shown_within, located, quote
from tofnet.io.safe_yaml import _line, _parse_yaml, kind_word, yaml_source

TOP_KEYS = ("name", "description", "output", "cache", "recordings", "networks", "grid", "backend", "keep",
            *READ_KEYS)
PATH_KEYS = ("path", "name", *READ_KEYS)
GLOB_KEYS = ("glob", *READ_KEYS)
SCENARIO_KEYS = ("scenario", "name", "duration", "seed", "sensor_size")
NETWORK_KEYS = ("spec", "name", "backend", "estimator", "rotation", "undistort")
KEEP = ("summary", "metrics", "depth")
DEFAULT_KEEP = ("summary", "metrics")
PAPER = "paper"


class PlanError(TofnetError):
    """A batch plan that cannot run: unknown key, missing file, bad value."""


@dataclass(frozen=True)
class RecordingSource:
    """One recording of a plan: a file or folder (``path``), or a built-in scenario to simulate.

    ``duration`` is in seconds and ``sensor_size`` in pixels (``None``: the scenario's).
    """

    name: str
    path: str | None = None
    scenario: str | None = None
    duration: float = 1.0
    seed: int = 0
    sensor_size: tuple[int, int] | None = None
    #: How a file is read (``tofnet.batch.reading``: intrinsics, calib, velocity, start, ...), as plain values.
    reading: tuple[tuple[str, Any], ...] = ()

    @property
    def options(self) -> dict[str, Any]:
        return dict(self.reading)

    @property
    def label(self) -> str:
        """What the table's ``recording`` column shows: the path, or ``scenario:NAME``."""
        return self.path if self.path is not None else f"scenario:{self.scenario}"


@dataclass(frozen=True)
class NetworkChoice:
    """One network of a plan: a YAML spec (``spec``; ``None``: the built-in network) and a backend.

    ``estimator``: the built-in network without a spec (``tofnet.api.ESTIMATORS``, as ``tofnet run
    --estimator``; ``None``: the paper's). ``allow_import``: the modules its spec may import
    (``tofnet.io.trust``), given to the workers. ``rotation`` / ``undistort`` False: as ``tofnet run
    --no-rotation`` / ``--no-undistort``.
    """

    name: str
    spec: str | None = None
    backend: str | None = None
    allow_import: tuple[str, ...] = ()
    estimator: str | None = None
    rotation: bool = True
    undistort: bool = True


@dataclass
class Plan:
    """A validated plan; ``grid`` maps an option name of ``tofnet run`` to its values, in plan order."""

    recordings: list[RecordingSource]
    networks: list[NetworkChoice]
    grid: dict[str, list[Any]]
    output: Path
    cache: Path
    keep: tuple[str, ...] = DEFAULT_KEEP
    backend: str | None = None
    name: str = "batch"
    description: str | None = None
    source: str = "<string>"
    base: Path = field(default_factory=Path.cwd)

    def combinations(self) -> list[dict[str, Any]]:
        """Every point of the grid (the Cartesian product, first key varying slowest)."""
        keys = list(self.grid)
        return [dict(zip(keys, values)) for values in itertools.product(*(self.grid[k] for k in keys))]

    def size(self) -> int:
        """Number of tasks: recordings x networks x grid points."""
        return len(self.recordings) * len(self.networks) * len(self.combinations())


def load_plan(path_or_text: str | Path, *, output: str | Path | None = None, allow_import: Any = None) -> Plan:
    """Read and validate a plan from a YAML file (a ``Path`` or a one-line ``.yaml`` name) or YAML text.

    Relative paths in the plan are relative to the plan file's folder (the working
    directory for text). ``output`` overrides the plan's ``output`` (relative: to the
    working directory). Every path of the plan comes out absolute, so tasks mean the same
    files on workers that run in other folders or on other machines. ``allow_import``: the
    modules its specs' ``module:Class`` types may import (``tofnet.io.trust``).
    """
    from tofnet.io.trust import allowed_imports
    try:  # the spec reader's file checks and YAML errors, already located
        text, source, path = yaml_source(path_or_text, "plan")
        tree = _parse_yaml(text, source, empty="empty plan; expected a mapping with recordings (and networks, grid)")
    except SpecError as err:
        raise PlanError(str(err)) from None
    base = path.resolve().parent if path is not None else Path.cwd()
    if output is not None:
        output = os.path.abspath(Path(output).expanduser())  # --out is the client's, relative to its cwd
    try:
        allow = allowed_imports(allow_import)
    except SpecError as err:
        raise PlanError(str(err)) from None
    with fields_shown_within(base, "the plan's folder"):  # a calib: file named absolutely is not quoted
        return _PlanReader(tree, source, base, allow).read(output)


class _PlanReader:
    """Turns a line-annotated YAML tree into a ``Plan``; every error names line and key."""

    def __init__(self, tree: Any, source: str, base: Path, allow: tuple[str, ...] = ()):
        self.tree, self.source, self.base, self.allow = tree, source, base, allow
        self.names: dict[str, int | None] = {}
        self.defaults: dict[str, Any] = {}  # plan-wide reading keys

    def fail(self, container: Any, key: Any, path: str, message: str) -> PlanError:
        return PlanError(located(self.source, _line(container, key), f"{path}: {message}"))

    def resolve(self, value: str, where: tuple = (), reads: bool = True) -> Path:
        """``value`` from the plan's folder; one it reads not out of it by ``..`` (the output and cache may be
        anywhere: they hold only what tofnet writes); ``where``: container, key, path an error names."""
        try:
            if reads:
                check_inside_plan(value)
        except TofnetError as err:
            raise (self.fail(*where, str(err)) if where else err) from None
        path = Path(value).expanduser()
        return path if path.is_absolute() else self.base / path

    def text(self, container: Mapping, key: str, path: str, default: str | None = None) -> str | None:
        if key in container and container[key] is None:  # `output:` alone is no default: it became "None-results"
            raise self.fail(container, key, path, "expected a non-empty string, got null (an empty value); "
                            "leave the key out for its default")
        value = container.get(key, default)
        if value is not None and (not isinstance(value, str) or not value.strip()):
            raise self.fail(container, key, path, f"expected a non-empty string, got {value!r}")
        return value

    def read(self, output: str | Path | None) -> Plan:
        tree = self.tree
        if not isinstance(tree, Mapping):
            raise PlanError(located(self.source, _line(tree), f"expected a mapping with keys {', '.join(TOP_KEYS)}; "
                                    f"got {kind_word(tree)}"))
        for key in tree:
            if key not in TOP_KEYS:
                raise self.fail(tree, key, str(key), f"unknown key; expected one of {', '.join(TOP_KEYS)}")
        name = self.text(tree, "name", "name", default=Path(self.source).stem if self.source != "<string>" else "batch")
        description = self.text(tree, "description", "description")
        out = Path(output) if output is not None else self.resolve(self.text(tree, "output", "output",
                                                                             default=f"{name}-results"), reads=False)
        cache = self.resolve(self.text(tree, "cache", "cache"), reads=False) if "cache" in tree else out / "scenarios"
        backend = self.backend(tree, "backend", "backend")
        keep = self.keep(tree)
        self.defaults = self.read_options(tree, {}, "")
        recordings = self.recordings(tree)
        networks = self.networks(tree)
        grid = read_grid(self, tree)
        try:  # from the sizes, before any grid point is made
            check_task_count(len(recordings), len(networks), [len(v) for v in grid.values()])
        except TofnetError as err:
            raise self.fail(tree, "grid" if "grid" in tree else "recordings", "grid", str(err)) from None
        plan = Plan(recordings, networks, grid, out, cache, keep, backend, name, description, self.source, self.base)
        check_grid(self, plan)
        return plan

    # ------------------------------------------------------------ sections

    def backend(self, container: Mapping, key: str, path: str) -> str | None:
        name = self.text(container, key, path)
        if name is not None:
            from tofnet.backends.registry import available_backends
            known = available_backends()
            if name not in known:
                raise self.fail(container, key, path, f"unknown backend {name!r}; expected one of {', '.join(known)}")
        return name

    def keep(self, tree: Mapping) -> tuple[str, ...]:
        if "keep" not in tree:
            return DEFAULT_KEEP
        value = tree["keep"]
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list):
            raise self.fail(tree, "keep", "keep", f"expected a list of {', '.join(KEEP)}, got {value!r}")
        for i, item in enumerate(items):
            if item not in KEEP:
                where = items if isinstance(value, list) else tree
                raise self.fail(where, i if isinstance(value, list) else "keep", f"keep[{i}]",
                                f"expected one of {', '.join(KEEP)}, got {item!r}")
        return tuple(k for k in KEEP if k in items)

    def recordings(self, tree: Mapping) -> list[RecordingSource]:
        if "recordings" not in tree:
            raise PlanError(located(self.source, _line(tree), "recordings: missing; expected a list of paths, "
                                    "globs or {scenario: NAME}"))
        section = tree["recordings"]
        if not isinstance(section, list) or not section:
            raise self.fail(tree, "recordings", "recordings", "expected a non-empty list of paths, globs or "
                            "{scenario: NAME}")
        out: list[RecordingSource] = []
        for i, entry in enumerate(section):
            path = f"recordings[{i}]"
            if isinstance(entry, str):
                found = self.glob(section, i, path, entry, self.defaults) if globbing.has_magic(entry) else \
                    [self.path(section, i, path, entry, None, self.defaults)]
            elif isinstance(entry, Mapping) and "scenario" in entry:
                found = self.scenarios(entry, path)
            elif isinstance(entry, Mapping) and "glob" in entry:
                self.only(entry, GLOB_KEYS, path, "a glob")
                found = self.glob(entry, "glob", f"{path}.glob", self.text(entry, "glob", f"{path}.glob"),
                                  self.read_options(entry, self.defaults, f"{path}."))
            elif isinstance(entry, Mapping) and "path" in entry:
                self.only(entry, PATH_KEYS, path, "a path")
                found = [self.path(entry, "path", f"{path}.path", self.text(entry, "path", f"{path}.path"),
                                   self.text(entry, "name", f"{path}.name"),
                                   self.read_options(entry, self.defaults, f"{path}."))]
            else:
                raise self.fail(section, i, path, f"expected a path, a glob, {{path: P, name: N}}, {{glob: G}} or "
                                f"{{scenario: NAME, duration: S, seed: N, sensor_size: WxH}}; got {entry!r}")
            for recording in found:
                self.unique(recording.name, section, i, path)
            out.extend(found)
        return out

    def only(self, entry: Mapping, keys: tuple[str, ...], path: str, what: str) -> None:
        for key in entry:
            if key not in keys:
                raise self.fail(entry, key, f"{path}.{key}", f"unknown key for {what}; expected {', '.join(keys)}")

    def unique(self, name: str, container: Any, key: Any, path: str) -> None:
        if name in self.names:
            first = self.names[name]
            raise self.fail(container, key, path, f"recording name {name!r} is already used"
                            f"{f' (line {first})' if first else ''}; give this one a name:")
        self.names[name] = _line(container, key)

    def read_options(self, entry: Mapping, defaults: dict[str, Any], where: str) -> dict[str, Any]:
        from tofnet.batch.reading import read_options
        return read_options(entry, defaults, where, self.fail, self.resolve)

    def path(self, container: Any, key: Any, path: str, value: str, name: str | None,
             options: dict[str, Any]) -> RecordingSource:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(container, key, path, f"expected a path, got {value!r}")
        resolved = self.resolve(value, (container, key, path))
        if not exists(resolved, Path.exists):
            hint = ("; a pattern is written {glob: ...} (with the same reading keys) to match several"
                    if any(c in value for c in "*?[") and isinstance(container, Mapping) else "")
            raise self.fail(container, key, path, located(resolved, None, f"no such file or folder{hint}"))
        return RecordingSource(name=name or _recording_name(resolved), path=str(resolved),
                               reading=tuple(options.items()))

    def glob(self, container: Any, key: Any, path: str, pattern: str,
             options: dict[str, Any]) -> list[RecordingSource]:
        full = self.resolve(pattern, reads=False)  # bounded_glob refuses a pattern out of the plan's folder
        try:
            matches = bounded_glob(pattern, self.base)
        except TofnetError as err:
            raise self.fail(container, key, path, str(err)) from None
        if not matches:
            raise self.fail(container, key, path, f"{quote(pattern)} matches nothing (looked for "
                            f"{located(full, None, '')[:-2]})")
        return [RecordingSource(name=_recording_name(m), path=str(m), reading=tuple(options.items()))
                for m in matches]

    def scenarios(self, entry: Mapping, path: str) -> list[RecordingSource]:
        from tofnet.core.params import parse_size
        from tofnet.sim import built_in_scenarios
        from tofnet.sim.config import MAX_DURATION_S
        self.only(entry, SCENARIO_KEYS, path, "a scenario")
        known = list(built_in_scenarios())
        names = entry["scenario"]
        names = known if names == "all" else [names] if isinstance(names, str) else names
        if not isinstance(names, list) or not names:
            raise self.fail(entry, "scenario", f"{path}.scenario", f"expected a name, a list of names or 'all'; "
                            f"got {entry['scenario']!r}")
        for j, name in enumerate(names):
            if name not in known:
                where = (entry["scenario"], j) if isinstance(entry["scenario"], list) else (entry, "scenario")
                raise self.fail(*where, f"{path}.scenario", f"unknown scenario {name!r}; expected one of "
                                f"{', '.join(known)} or all")
        duration = entry.get("duration", 1.0)
        if isinstance(duration, str):
            from tofnet.units import seconds
            try:
                duration = seconds(duration, f"{path}.duration")
            except TofnetError as err:
                raise self.fail(entry, "duration", f"{path}.duration", str(err).split(": ", 1)[-1]) from None
        if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not math.isfinite(duration) \
                or not 0 < duration <= MAX_DURATION_S:
            raise self.fail(entry, "duration", f"{path}.duration", f"expected a positive number of seconds, at "
                            f"most {MAX_DURATION_S:g}, got {quote(entry.get('duration'))}")
        seeds = entry.get("seed", 0)
        seeds = seeds if isinstance(seeds, list) else [seeds]
        if not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
            raise self.fail(entry, "seed", f"{path}.seed", f"expected a non-negative integer or a list of them, "
                            f"got {entry.get('seed')!r}")
        size = None
        if "sensor_size" in entry:
            try:
                size = parse_size(entry["sensor_size"], f"{path}.sensor_size")
            except TofnetError as err:
                raise self.fail(entry, "sensor_size", f"{path}.sensor_size", str(err).split(": ", 1)[-1]) from None
        name = self.text(entry, "name", f"{path}.name")
        if name is not None and len(names) * len(seeds) > 1:
            raise self.fail(entry, "name", f"{path}.name", "a name fits one scenario and one seed; "
                            "several are named after the scenario (and -seedN)")
        return [RecordingSource(name=name or (s if len(seeds) == 1 else f"{s}-seed{seed}"), scenario=s,
                                duration=float(duration), seed=int(seed), sensor_size=size)
                for s in names for seed in seeds]

    def networks(self, tree: Mapping) -> list[NetworkChoice]:
        section = tree.get("networks", [PAPER])
        if not isinstance(section, list) or not section:
            raise self.fail(tree, "networks", "networks", f"expected a non-empty list of spec files or {PAPER!r}")
        out, names = [], {}
        for i, entry in enumerate(section):
            path = f"networks[{i}]"
            container, key = section, i
            if isinstance(entry, str):
                entry = {"spec": entry}
            elif not isinstance(entry, Mapping):
                raise self.fail(section, i, path, f"expected a spec file, {PAPER!r} or {{spec: FILE, name: N, "
                                f"backend: B}}; got {entry!r}")
            else:
                self.only(entry, NETWORK_KEYS, path, "a network")
                container, key = entry, "spec"
            spec = entry.get("spec", PAPER)
            if not isinstance(spec, str) or not spec.strip():
                raise self.fail(container, key, path, f"expected a spec file or {PAPER!r}, got {spec!r}")
            resolved = None
            if spec != PAPER:
                resolved = self.resolve(spec, (container, key, f"{path}.spec" if container is entry else path))
                self.load_spec(resolved, container, key, f"{path}.spec" if container is entry else path)
            estimator = self.estimator(entry, resolved, path) if container is entry else None
            name = self.text(entry, "name", f"{path}.name") if container is entry else None
            name = name or estimator or (PAPER if resolved is None else resolved.stem)
            if name in names:
                raise self.fail(container, key, path, f"network name {name!r} is already used (line {names[name]}); "
                                "give this one a name:")
            names[name] = _line(container, key)
            backend = self.backend(entry, "backend", f"{path}.backend") if container is entry else None
            switches = {key: self.switch(entry, key, f"{path}.{key}") for key in ("rotation", "undistort")
                        if container is entry}
            out.append(NetworkChoice(name=name, spec=None if resolved is None else str(resolved), backend=backend,
                                     allow_import=self.allow, estimator=estimator, **switches))
        return out

    def switch(self, entry: Mapping, key: str, path: str) -> bool:
        """A network entry's ``rotation:`` / ``undistort:`` (true or false; default true)."""
        value = entry.get(key, True)
        if not isinstance(value, bool):
            raise self.fail(entry, key, path, f"expected true or false (false: as tofnet run --no-{key}), "
                            f"got {value!r}")
        return value

    def estimator(self, entry: Mapping, spec: Path | None, path: str) -> str | None:
        """A network entry's ``estimator:`` (``tofnet run --estimator``): a built-in network, so no spec file."""
        from tofnet.api import ESTIMATORS
        name = self.text(entry, "estimator", f"{path}.estimator")
        if name is None:
            return None
        if name not in ESTIMATORS:
            raise self.fail(entry, "estimator", f"{path}.estimator", f"expected one of {', '.join(ESTIMATORS)}, "
                            f"got {name!r}")
        if spec is not None:
            raise self.fail(entry, "estimator", f"{path}.estimator", "picks a built-in network, and a spec names "
                            "its own processes; give one or the other")
        return name

    def load_spec(self, spec: Path, container: Any, key: Any, path: str) -> None:
        from tofnet.io.spec import load_spec
        if not exists(spec, Path.is_file):
            raise self.fail(container, key, path, located(spec, None, "no such spec file"))
        load_spec(spec, allow_import=self.allow)  # a SpecError names the spec's own file, line and key


def _recording_name(path: Path) -> str:
    """A recording's default name: its dataset sequence's (``sequence_name``: also for the events file in a
    DSEC folder), its folder name, or its file name without the suffix."""
    from tofnet.io.layouts import sequence_name
    return sequence_name(path) or (path.name if path.is_dir() else path.stem)
