"""YAML network specs: a network, how to compile it and which backend runs it.

``load_spec`` reads a spec (a file or YAML text) into a ``Spec``; ``dump_spec`` writes
one back. Every process type, parameter and connection of the Python API can be
written; errors name the file, the line and the key. The format is in docs/spec.md.
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from importlib.resources import files
from pathlib import Path
from typing import Any, Mapping

import yaml

from tofnet.compiler.budget import LOIHI2, Budget, budget_name_or_dict
from tofnet.compiler.partition import parse_patch_size, patch_per_layer
from tofnet.core.network import Network
from tofnet.core.ports import InPort, OutPort
from tofnet.core.process import Process
from tofnet.errors import SpecError, TofnetError, located
from tofnet.units import seconds

TOP_KEYS = ("name", "description", "processes", "connections", "compile", "backend")
COMPILE_KEYS = ("patch", "budget")
_CONNECTION = re.compile(r"^\s*(\w+)\.(\w+)\s*->\s*(\w+)\.(\w+)\s*$")
# YAML 1.1 (PyYAML) reads 1e-3 as a string; YAML 1.2 and people read it as a number.
_FLOAT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")


@dataclass
class Spec:
    """A loaded spec: the network, compile options, backend and where it came from.

    ``compile`` holds the keys the spec gave, as ``compile_network`` takes them:
    ``budget`` (a ``Budget``) and ``patch`` (``"auto"``, ``(w, h)`` px or per process).
    """

    network: Network
    compile: dict[str, Any] = field(default_factory=dict)
    backend: str | None = None
    backend_options: dict[str, Any] = field(default_factory=dict)
    description: str | None = None
    source: str = "<string>"

    @property
    def budget(self) -> Budget:
        return self.compile.get("budget", LOIHI2)

    def compile_network(self, **overrides: Any):
        """``compile_network(network, **compile)``, with ``overrides`` (budget, patch) applied."""
        from tofnet.compiler import compile_network
        return compile_network(self.network, **{**self.compile, **overrides})


# ---------------------------------------------------------------- reading YAML with line numbers

class _Map(dict):
    """A mapping that remembers its line and the line of each key (1-based)."""

    line: int | None = None
    key_lines: dict = {}


class _Seq(list):
    """A list that remembers its line and the line of each item (1-based)."""

    line: int | None = None
    item_lines: list = []


def _parse_yaml(text: str, source: str, empty: str = "empty spec; expected a mapping with processes and connections"
                ) -> Any:
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        where = f" (column {mark.column + 1})" if mark else ""
        raise SpecError(located(source, mark.line + 1 if mark else None, f"malformed YAML: {problem}{where}")) from None
    if node is None:
        raise SpecError(located(source, None, empty))
    return _build(node, yaml.SafeLoader(""), source)


def _build(node: yaml.Node, loader: yaml.SafeLoader, source: str) -> Any:
    line = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        loader.flatten_mapping(node)  # YAML merge keys (<<)
        out = _Map()
        out.line, out.key_lines = line, {}
        for key_node, value_node in node.value:
            key = _build(key_node, loader, source)
            key_line = key_node.start_mark.line + 1
            if isinstance(key, (dict, list)):
                raise SpecError(located(source, key_line, "a mapping key must be a plain value"))
            if key in out:
                raise SpecError(located(source, key_line, f"duplicate key {key!r} (first on line {out.key_lines[key]})"))
            out[key] = _build(value_node, loader, source)
            out.key_lines[key] = key_line
        return out
    if isinstance(node, yaml.SequenceNode):
        out = _Seq(_build(item, loader, source) for item in node.value)
        out.line, out.item_lines = line, [item.start_mark.line + 1 for item in node.value]
        return out
    if node.tag == "tag:yaml.org,2002:str" and node.style is None and _FLOAT.match(node.value):
        return float(node.value)
    return loader.construct_object(node, deep=True)


def _line(container: Any, key: Any = None) -> int | None:
    """Line of ``container[key]`` (or of the container) when it came from YAML."""
    if key is not None:
        if isinstance(container, _Map) and key in container.key_lines:
            return container.key_lines[key]
        if isinstance(container, _Seq) and isinstance(key, int) and key < len(container.item_lines):
            return container.item_lines[key]
    return getattr(container, "line", None)


class _Reader:
    """Turns a (line-annotated) tree into a ``Spec``; every error names line and key."""

    def __init__(self, tree: Any, source: str):
        self.tree, self.source = tree, source

    def fail(self, container: Any, key: Any, path: str, message: str) -> SpecError:
        return SpecError(located(self.source, _line(container, key), f"{path}: {message}"))

    def line_of_path(self, path: str) -> int | None:
        # "compile.budget.core.neurons" -> line of the deepest key that exists.
        node, line = self.tree, _line(self.tree)
        for part in path.split("."):
            if isinstance(node, Mapping) and part in node:
                line, node = _line(node, part) or line, node[part]
            else:
                break
        return line

    def relocate(self, err: TofnetError) -> SpecError:
        """An error whose message starts with a key path, placed on that key's line."""
        message = str(err)
        path = message.split(":", 1)[0]
        return SpecError(located(self.source, self.line_of_path(path), message))

    def read(self) -> Spec:
        tree = self.tree
        if not isinstance(tree, Mapping):
            raise SpecError(located(self.source, _line(tree), "expected a mapping with keys "
                                    f"{', '.join(TOP_KEYS)}; got {type(tree).__name__}"))
        for key in tree:
            if key not in TOP_KEYS:
                raise self.fail(tree, key, str(key), f"unknown key; expected one of {', '.join(TOP_KEYS)}")
        name = tree.get("name", "network")
        if not isinstance(name, str):
            raise self.fail(tree, "name", "name", f"expected a string, got {name!r}")
        description = tree.get("description")
        if description is not None and not isinstance(description, str):
            raise self.fail(tree, "description", "description", f"expected a string, got {description!r}")
        processes = self.processes(tree)
        self.connections(tree, processes)
        try:
            network = Network(processes.values(), name=name)
        except TofnetError as err:
            raise self.network_error(err, processes) from None
        compile_options = self.compile(tree, network)
        backend, options = self.backend(tree)
        return Spec(network, compile_options, backend, options, description, self.source)

    def processes(self, tree: Mapping) -> dict[str, Process]:
        if "processes" not in tree:
            raise SpecError(located(self.source, _line(tree), "processes: missing; expected a mapping "
                                    "name: {type: ProcessType, parameter: value, ...}"))
        section = tree["processes"]
        if not isinstance(section, Mapping) or not section:
            raise self.fail(tree, "processes", "processes",
                            "expected a mapping name: {type: ProcessType, parameter: value, ...}")
        out = {}
        for name, body in section.items():
            path = f"processes.{name}"
            if not isinstance(body, Mapping):
                raise self.fail(section, name, path, f"expected a mapping with type: and parameters, got {body!r}")
            if "type" not in body:
                raise self.fail(section, name, path, f"missing type; expected one of {', '.join(_known_types())}")
            cls = self.process_type(body, path)
            declared = {p.name: p for p in cls.all_params()}
            values = {}
            for key, raw in body.items():
                if key == "type":
                    continue
                if key not in declared:
                    raise self.fail(body, key, f"{path}.{key}", f"unknown parameter of {cls.__name__}; "
                                    f"expected {', '.join(declared)}")
                try:
                    declared[key].coerce(raw, str(name))
                except TofnetError as err:
                    raise self.fail(body, key, f"{path}.{key}", _strip_field(str(err), f"{name}.{key}")) from None
                values[key] = raw
            try:
                out[name] = cls(name=name, **values)
            except TofnetError as err:
                raise self.fail(section, name, path, str(err)) from None
        return out

    def process_type(self, body: Mapping, path: str) -> type[Process]:
        type_name = body["type"]
        if isinstance(type_name, str):
            try:
                found = process_class(type_name)
            except TofnetError as err:
                raise self.fail(body, "type", f"{path}.type", str(err)) from None
            if found is not None:
                return found
        raise self.fail(body, "type", f"{path}.type",
                        f"unknown process type {type_name!r}; expected one of {', '.join(_known_types())}, "
                        "'package.module:ClassName' or a 'tofnet.processes' entry point")

    def connections(self, tree: Mapping, processes: dict[str, Process]) -> None:
        section = tree.get("connections") or []
        if not isinstance(section, list):
            raise self.fail(tree, "connections", "connections",
                            "expected a list of 'process.port -> process.port' strings")
        for i, item in enumerate(section):
            path = f"connections[{i}]"
            match = _CONNECTION.match(item) if isinstance(item, str) else None
            if not match:
                raise self.fail(section, i, path, f"expected 'process.port -> process.port', got {item!r}")
            ends = []
            for proc_name, port_name in (match.group(1, 2), match.group(3, 4)):
                if proc_name not in processes:
                    raise self.fail(section, i, path, f"unknown process {proc_name!r}; "
                                    f"processes: {', '.join(processes)}")
                process = processes[proc_name]
                if port_name not in process.ports:
                    raise self.fail(section, i, path, f"unknown port {port_name!r} of {proc_name} "
                                    f"({type(process).__name__}); ports: {_ports(process)}")
                ends.append(process.ports[port_name])
            source, target = ends
            if not isinstance(source, OutPort) or not isinstance(target, InPort):
                raise self.fail(section, i, path, f"{item.strip()}: a connection goes from an output port to an "
                                f"input port (outputs of {source.process.name}: {_ports(source.process, OutPort)}; "
                                f"inputs of {target.process.name}: {_ports(target.process, InPort)})")
            try:
                source.connect(target)
            except TofnetError as err:
                raise self.fail(section, i, path, str(err)) from None

    def network_error(self, err: TofnetError, processes: dict[str, Process]) -> SpecError:
        # Point at the first process the message names: a port (``depth.a_t``) first,
        # else the bare name; validation messages name ports.
        message = str(err)
        found = []
        for pattern in (r"(?<![\w.]){}\.\w", r"(?<![\w.]){}(?!\w)"):
            found = [(m.start(), name) for name in processes
                     for m in [re.search(pattern.format(re.escape(name)), message)] if m]
            if found:
                break
        if not found:
            return SpecError(located(self.source, _line(self.tree, "connections"), message))
        name = min(found)[1]
        return self.fail(self.tree["processes"], name, f"processes.{name}", message)

    def compile(self, tree: Mapping, network: Network) -> dict[str, Any]:
        section = tree.get("compile")
        if section is None:
            return {}
        if not isinstance(section, Mapping):
            raise self.fail(tree, "compile", "compile", "expected a mapping with patch and budget")
        out: dict[str, Any] = {}
        for key in section:
            if key not in COMPILE_KEYS:
                raise self.fail(section, key, f"compile.{key}", f"unknown key; expected {', '.join(COMPILE_KEYS)}")
        try:
            if "budget" in section:
                out["budget"] = Budget.from_dict(section["budget"], where="compile.budget")
            if "patch" in section:
                out["patch"] = patch_from_data(section["patch"])
                layers = [p.name for p in network.processes if p.placement == "core"]
                patch_per_layer(out["patch"], layers, where="compile.patch")
        except TofnetError as err:
            raise self.relocate(err) from None
        return out

    def backend(self, tree: Mapping) -> tuple[str | None, dict[str, Any]]:
        value = tree.get("backend")
        if value is None or isinstance(value, str):
            return value, {}
        if isinstance(value, Mapping) and isinstance(value.get("name"), str):
            return value["name"], {k: v for k, v in value.items() if k != "name"}
        raise self.fail(tree, "backend", "backend", "expected a backend name (fixed) or a mapping "
                        f"{{name: fixed, option: value, ...}}, got {value!r}")


def _strip_field(message: str, field_name: str) -> str:
    prefix = f"{field_name}: "
    return message[len(prefix):] if message.startswith(prefix) else message


def _known_types() -> list[str]:
    return sorted(set(Process._registry) | {ep.name for ep in entry_points(group=ENTRY_POINTS)})


#: Entry-point group through which installed packages offer process types to specs.
ENTRY_POINTS = "tofnet.processes"


def process_class(type_name: str) -> type[Process] | None:
    """The process class a spec's ``type`` names, None when unknown.

    In order: ``package.module:ClassName`` (imported; running its module is what registers
    its models), a class already imported (``DepthProcess`` or ``Depth``), a
    ``tofnet.processes`` entry point of that name. Raises when an import fails or names
    something that is not a process type.
    """
    if ":" in type_name:
        module_name, _, attr = type_name.partition(":")
        try:
            module = importlib.import_module(module_name)
        except Exception as err:  # the user's module: whatever it raises, one line
            raise SpecError(f"cannot import {module_name!r} for process type {type_name!r}: "
                            f"{type(err).__name__}: {err}") from None
        found = getattr(module, attr, None)
        if not (isinstance(found, type) and issubclass(found, Process)):
            raise SpecError(f"{type_name!r} is not a process type (a subclass of tofnet.Process)")
        return found
    for candidate in (type_name, type_name + "Process"):
        if candidate in Process._registry:
            return Process._registry[candidate]
    for ep in entry_points(group=ENTRY_POINTS):
        if ep.name == type_name:
            try:
                found = ep.load()
            except Exception as err:
                raise SpecError(f"entry point {ENTRY_POINTS}:{type_name} failed to load: "
                                f"{type(err).__name__}: {err}") from None
            if isinstance(found, type) and issubclass(found, Process):
                return found
            raise SpecError(f"entry point {ENTRY_POINTS}:{type_name} is not a process type")
    return None


def type_name_of(process: Process) -> str:
    """How a spec names the type of ``process``: the class name for tofnet's own and for
    classes a script defines, else ``package.module:ClassName`` (importable in a new process)."""
    cls = type(process)
    if cls.__module__.startswith("tofnet.processes") or cls.__module__ in ("__main__", "__mp_main__"):
        return cls.__name__
    return f"{cls.__module__}:{cls.__qualname__}"


def _ports(process: Process, kind: type = object) -> str:
    return ", ".join(name for name, port in process.ports.items() if isinstance(port, kind)) or "(none)"


# ---------------------------------------------------------------- public API

def load_spec(path_or_text: str | Path) -> Spec:
    """Read a spec from a file path or from YAML text.

    A ``Path``, or a one-line string naming a file, is read as a file; any other string
    is YAML text. Raises ``SpecError`` naming the file, line and key.
    """
    if isinstance(path_or_text, Path) or ("\n" not in path_or_text and (
            path_or_text.endswith((".yaml", ".yml")) or Path(path_or_text).is_file())):
        path = Path(path_or_text)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise SpecError(f"{path}: cannot read the spec: {getattr(err, 'strerror', None) or err}") from None
        source = str(path)
    else:
        text, source = path_or_text, "<string>"
    return _Reader(_parse_yaml(text, source), source).read()


def spec_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> Spec:
    """A spec from plain data (as ``spec_to_dict`` returns); errors name keys, not lines."""
    return _Reader(data, source).read()


def network_from_dict(data: Mapping[str, Any], source: str = "<dict>") -> Network:
    """The network of plain spec data (``name``, ``processes``, ``connections``)."""
    return spec_from_dict({k: v for k, v in data.items() if k in ("name", "processes", "connections")},
                          source).network


def network_to_dict(network: Network, full: bool = False) -> dict[str, Any]:
    """``name``, ``processes`` and ``connections`` as plain data.

    ``full=False`` writes only parameters that differ from their defaults (plus the
    sensor size of sources, which others inherit); ``full=True`` writes every one.
    """
    processes = {}
    for process in network.processes:
        body: dict[str, Any] = {"type": type_name_of(process)}
        for param in type(process).all_params():
            value = process.values[param.name]
            if not full and not _worth_writing(process, param, value):
                continue
            body[param.name] = _to_data(param.kind, value)
        processes[process.name] = body
    connections = [f"{s.qualified_name} -> {t.qualified_name}" for s, t in network.connections()]
    return {"name": network.name, "processes": processes, "connections": connections}


def _worth_writing(process: Process, param, value: Any) -> bool:
    if param.name == "sensor_size":
        # Inherited sizes are left out; a source with its own default (the input) keeps it. Only spikes
        # carry pixels: a process fed by fields alone (the time surface, from A t) is a source too.
        fed = any(isinstance(p, InPort) and p.source is not None and p.spec.payload.kind == "spikes"
                  for p in process.ports.values())
        feeds = any(isinstance(p, OutPort) and p.targets for p in process.ports.values())
        return value is not None and not fed and (param.default is not None or not feeds)
    try:
        default = param.coerce(param.default, process.name)
    except TofnetError:
        return True
    return value != default


def _to_data(kind: str, value: Any) -> Any:
    if value is None:
        return None
    if kind == "duration":
        return _duration_text(value)
    if kind in ("size", "vector3", "floats"):
        return list(value)
    return value


def _duration_text(value: float) -> Any:
    """``0.001`` -> ``"1ms"`` when that reads back exactly, else the number in seconds."""
    if value == 0:
        return 0
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6)):
        number = value / scale
        if 1 <= abs(number) < 1000 or unit == "us":
            text = f"{number:.12g}{unit}"
            if "e" not in text and seconds(text) == value:
                return text
    return value


def patch_to_data(patch: Any) -> Any:
    """A ``patch`` option as plain data: ``"auto"``, ``[w, h]`` or ``{process: ...}``."""
    if patch is None or isinstance(patch, str):
        return patch
    if isinstance(patch, Mapping):
        return {name: patch_to_data(v) for name, v in patch.items()}
    if isinstance(patch, int):
        return [patch, patch]
    return list(patch)


def patch_from_data(data: Any, where: str = "compile.patch") -> Any:
    """Inverse of ``patch_to_data``; checks sizes (``BudgetError`` naming ``where``)."""
    if data is None:
        return None
    if isinstance(data, Mapping):
        return {name: parse_patch_size(v, f"{where}.{name}") for name, v in data.items()}
    return parse_patch_size(data, where)


def spec_to_dict(spec: Spec | Network, full: bool = False) -> dict[str, Any]:
    """A spec (or a bare network) as plain data, ready for YAML or JSON."""
    if isinstance(spec, Network):
        spec = Spec(spec)
    out = network_to_dict(spec.network, full=full)
    if spec.description:
        out = {"name": out.pop("name"), "description": spec.description, **out}
    compile_data = {}
    if "patch" in spec.compile:
        compile_data["patch"] = patch_to_data(spec.compile["patch"])
    if "budget" in spec.compile:
        compile_data["budget"] = budget_name_or_dict(spec.compile["budget"])
    if compile_data:
        out["compile"] = compile_data
    if spec.backend:
        out["backend"] = {"name": spec.backend, **spec.backend_options} if spec.backend_options else spec.backend
    return out


def dump_spec(spec: Spec | Network, full: bool = False) -> str:
    """YAML text for a spec or a network; ``load_spec`` reads it back to an equal network."""
    data = spec_to_dict(spec, full=full)
    lines = [f"name: {_flow(data['name'])}"]
    if "description" in data:
        lines.append(f"description: {_flow(data['description'])}")
    lines.append("processes:")
    lines += [f"  {_flow(name)}: {_flow(body)}" for name, body in data["processes"].items()]
    lines.append("connections:")
    lines += [f"  - {_flow(c)}" for c in data["connections"]]
    for key in ("compile", "backend"):
        if key in data:
            nested = isinstance(data[key], Mapping) and any(isinstance(v, Mapping) for v in data[key].values())
            if nested:
                block = yaml.safe_dump({key: data[key]}, sort_keys=False, default_flow_style=None)
                lines.append(block.rstrip())
            else:
                lines.append(f"{key}: {_flow(data[key])}")
    return "\n".join(lines) + "\n"


def _flow(value: Any) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, width=1 << 30, sort_keys=False, allow_unicode=True)
    text = text.strip()
    return text[:-3].rstrip() if text.endswith("\n...") else text


def network_signature(network: Network) -> dict[str, Any]:
    """What makes two networks equal: process names, types, parameter values and connections."""
    return {"processes": {p.name: (type_name_of(p), p.values) for p in network.processes},
            "connections": sorted(f"{s.qualified_name} -> {t.qualified_name}" for s, t in network.connections())}


def networks_equal(a: Network, b: Network) -> bool:
    """Same processes (name, type, parameter values) and the same connections."""
    return network_signature(a) == network_signature(b)


def default_spec_path() -> Path:
    """The built-in spec: the paper's network at 240x180, 1 ms steps, 30x30 patches."""
    return Path(str(files("tofnet").joinpath("specs", "default.yaml")))


def load_budget(path_or_name: str | Path) -> Budget:
    """A budget from a built-in name or a YAML file.

    The file holds a budget mapping (``core``, ``chip``, ``max_chips``), a ``budget:``
    key, or a whole spec whose ``compile.budget`` is used.
    """
    from tofnet.compiler.budget import BUDGETS
    if isinstance(path_or_name, str) and path_or_name in BUDGETS:
        return BUDGETS[path_or_name]
    path = Path(path_or_name)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise SpecError(f"{path}: cannot read the budget ({err.strerror}); expected a YAML file or one of "
                        f"{', '.join(BUDGETS)}") from None
    tree = _parse_yaml(text, str(path), "empty budget file; expected a mapping with core, chip, max_chips")
    reader = _Reader(tree, str(path))
    where, data = "budget", tree
    if isinstance(tree, Mapping) and "processes" in tree:
        where = "compile.budget"
        data = (tree.get("compile") or {}).get("budget", "loihi2")
    elif isinstance(tree, Mapping) and "budget" in tree:
        data = tree["budget"]
    elif isinstance(tree, Mapping):
        where = ""
    try:
        return Budget.from_dict(data, where=where or "budget")
    except TofnetError as err:
        if not where:
            # Top-level budget mapping: paths in messages start with "budget." but keys do not.
            message = str(err)
            path_part = message.split(":", 1)[0].removeprefix("budget.")
            raise SpecError(located(str(path), reader.line_of_path(path_part), message)) from None
        raise reader.relocate(err) from None
