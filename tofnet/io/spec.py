"""YAML network specs: a network, how to compile it and which backend runs it.

``load_spec`` reads a spec (a file or YAML text) into a ``Spec`` (``tofnet.io.spec_data``);
``dump_spec`` (``tofnet.io.spec_writer``) writes one back. Every process type, parameter and connection
of the Python API can be written; errors name the file, the line and the key. The format
is in docs/spec.md. YAML is read by the bounded safe loader of ``tofnet.io.safe_yaml``.
"""

from __future__ import annotations

import importlib
import re
from importlib.metadata import entry_points
from importlib.resources import files
from pathlib import Path
from typing import Any, Iterable, Mapping

from tofnet.compiler.budget import Budget
from tofnet.compiler.partition import parse_patch_size, patch_per_layer
from tofnet.core.network import Network
from tofnet.core.ports import InPort, OutPort
from tofnet.core.process import Process
from tofnet.errors import SpecError, TofnetError, field_hidden, located, quote, reason, shown_path
from tofnet.io.safe_yaml import (MAX_SPEC_BYTES, _Map, _Seq, _line, _parse_yaml, _read_spec_file,  # noqa: F401
                                 kind_word, read_yaml_file, yaml_source)
from tofnet.io.spec_data import Spec
from tofnet.io.trust import ENTRY_POINTS, allowed_imports, check_import, file_a_spec_names
from tofnet.io.spec_writer import (dump_spec, network_signature, network_to_dict, networks_equal,  # noqa: F401
                                   patch_to_data, spec_to_dict, type_name_of)
TOP_KEYS = ("name", "description", "processes", "connections", "compile", "backend")
COMPILE_KEYS = ("patch", "budget")
_CONNECTION = re.compile(r"^\s*(\w+)\.(\w+)\s*->\s*(\w+)\.(\w+)\s*$")


class _Reader:
    """Turns a (line-annotated) tree into a ``Spec``; every error names line and key."""

    def __init__(self, tree: Any, source: str, allow_import: Any = None, folder: Path | None = None,
                 replaced: Iterable[str] = ()):
        self.tree, self.source = tree, source
        self.allow, self.folder = allowed_imports(allow_import), folder
        # PROCESS.PARAM (or ProcessType.PARAM) the caller sets after loading: not the spec's file
        self.replaced = frozenset(replaced)

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
                                    f"{', '.join(TOP_KEYS)}; got {kind_word(tree)}"))
        for key in tree:
            if key not in TOP_KEYS:
                raise self.fail(tree, key, str(key), f"unknown key; expected one of {', '.join(TOP_KEYS)}")
        name = tree.get("name", "network")
        if not isinstance(name, str):
            raise self.fail(tree, "name", "name", f"expected a string, got {quote(name)}")
        description = tree.get("description")
        if description is not None and not isinstance(description, str):
            raise self.fail(tree, "description", "description", f"expected a string, got {quote(description)}")
        processes = self.processes(tree)
        self.connections(tree, processes)
        try:
            network = Network(processes.values(), name=name)
        except TofnetError as err:
            raise self.network_error(err, processes) from None
        compile_options = self.compile(tree, network)
        backend, options = self.backend(tree)
        section = tree.get("backend")
        lines = {"": _line(tree, "backend"), **{str(key): _line(section, key) for key in options}}
        return Spec(network, compile_options, backend, options, description, self.source, lines)

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
            if not isinstance(name, str) or not name.isidentifier():
                raise self.fail(section, name, f"processes.{quote(name)}",
                                "a process name must be an identifier (letters, digits, _)")
            if not isinstance(body, Mapping):
                raise self.fail(section, name, path, f"expected a mapping with type: and parameters, got {quote(body)}")
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
                    if self.folder is not None and declared[key].reads_file and isinstance(raw, str) \
                            and not {f"{name}.{key}", f"{cls.__name__}.{key}"} & self.replaced:
                        raw = file_a_spec_names(raw, self.folder, f"{name}.{key}")
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
                found = process_class(type_name, allow_import=self.allow, spec_dir=self.folder)
            except TofnetError as err:
                raise self.fail(body, "type", f"{path}.type", str(err)) from None
            if found is not None:
                return found
        raise self.fail(body, "type", f"{path}.type",
                        f"unknown process type {quote(type_name)}; expected one of {', '.join(_known_types())}, "
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
                raise self.fail(section, i, path, f"expected 'process.port -> process.port', got {quote(item)}")
            ends = []
            for proc_name, port_name in (match.group(1, 2), match.group(3, 4)):
                if proc_name not in processes:
                    raise self.fail(section, i, path, f"unknown process {quote(proc_name)}; "
                                    f"processes: {', '.join(processes)}")
                process = processes[proc_name]
                if port_name not in process.ports:
                    raise self.fail(section, i, path, f"unknown port {quote(port_name)} of {proc_name} "
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
                        f"{{name: fixed, option: value, ...}}, got {quote(value)}")


def _strip_field(message: str, field_name: str) -> str:
    prefix = f"{field_name}: "
    return message[len(prefix):] if message.startswith(prefix) else message


def _known_types() -> list[str]:
    return sorted(set(Process._registry) | {ep.name for ep in entry_points(group=ENTRY_POINTS)})



def process_class(type_name: str, *, allow_import: Any = None, spec_dir: Path | None = None) -> type[Process] | None:
    """The process class a spec's ``type`` names, None when unknown.

    In order: ``package.module:ClassName`` (imported, only when ``tofnet.io.trust.check_import``
    allows it: ``allow_import`` names the module, or it is already imported; running its
    module is what registers its models), a class already imported (``DepthProcess`` or
    ``Depth``), a ``tofnet.processes`` entry point of that name. Raises when an import is
    refused or fails, or names something that is not a process type.
    """
    if ":" in type_name:
        allow = allow_import if isinstance(allow_import, tuple) else allowed_imports(allow_import)
        module_name = check_import(type_name, allow, spec_dir)  # before anything is imported
        attr = type_name.partition(":")[2]
        try:
            module = importlib.import_module(module_name)
        except (Exception, SystemExit) as err:  # the user's module: whatever it raises (exits too), one line
            raise SpecError(f"cannot import {quote(module_name)} for process type {quote(type_name)}: "
                            f"{type(err).__name__}: {reason(err)}") from None
        found = getattr(module, attr, None)
        if found is None:
            raise SpecError(f"{quote(type_name)}: module {quote(module_name)} has no {quote(attr)}")
        if not (isinstance(found, type) and issubclass(found, Process)) or found is Process:
            raise SpecError(f"{quote(type_name)} is not a process type (a subclass of tofnet.Process)")
        return found
    for candidate in (type_name, type_name + "Process"):
        if candidate in Process._registry:
            ambiguous = Process.ambiguity(candidate)
            if ambiguous:
                raise SpecError(ambiguous)
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


def _ports(process: Process, kind: type = object) -> str:
    return ", ".join(name for name, port in process.ports.items() if isinstance(port, kind)) or "(none)"


# ---------------------------------------------------------------- public API

def load_spec(path_or_text: str | Path, *, allow_import: Any = None, replaced: Iterable[str] = ()) -> Spec:
    """Read a spec from a file path or from YAML text.

    A ``Path``, or a one-line string naming a file, is read as a file; any other string
    is YAML text. Raises ``SpecError`` naming the file, line and key. ``allow_import``:
    the modules its ``module:Class`` types may import (``tofnet.io.trust``). A file a spec file
    names must lie in its folder (``tofnet.io.trust.file_a_spec_names``), except for the
    parameters in ``replaced`` (``PROCESS.PARAM`` or ``ProcessType.PARAM``), which the caller sets
    after loading; YAML text given here is the caller's own, and its names are kept as written.
    """
    text, source, path = yaml_source(path_or_text, "spec")
    folder = path.resolve().parent if path is not None else None
    try:
        return _Reader(_parse_yaml(text, source), source, allow_import, folder, replaced).read()
    except SpecError as err:
        hidden = field_hidden(path) if path is not None else None
        if hidden is None:
            raise
        # a batch plan may name a spec anywhere: the line of the fault, not the keys and values around it
        line = re.match(rf"{re.escape(shown_path(source))}:(\d+): ", str(err))
        raise SpecError(located(source, int(line.group(1)) if line else None,
                                f"not a spec tofnet can load: {hidden}; 'tofnet compile FILE' shows the fault")) from None


def spec_from_dict(data: Mapping[str, Any], source: str = "<dict>", *, allow_import: Any = None) -> Spec:
    """A spec from plain data (as ``spec_to_dict`` returns); errors name keys, not lines."""
    return _Reader(data, source, allow_import).read()


def network_from_dict(data: Mapping[str, Any], source: str = "<dict>", *, allow_import: Any = None) -> Network:
    """The network of plain spec data (``name``, ``processes``, ``connections``)."""
    return spec_from_dict({k: v for k, v in data.items() if k in ("name", "processes", "connections")},
                          source, allow_import=allow_import).network


def patch_from_data(data: Any, where: str = "compile.patch") -> Any:
    """Inverse of ``patch_to_data``; checks sizes (``BudgetError`` naming ``where``)."""
    if data is None:
        return None
    if isinstance(data, Mapping):
        return {name: parse_patch_size(v, f"{where}.{name}") for name, v in data.items()}
    return parse_patch_size(data, where)


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
    if not (path.exists() or path.is_symlink()):
        raise SpecError(located(path, None, f"cannot read the budget (no such file); expected a YAML file or one "
                                            f"of {', '.join(BUDGETS)}"))
    text = _read_spec_file(path, "budget")
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
