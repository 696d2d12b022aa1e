"""Networks and specs as plain data and YAML text (what ``load_spec`` reads back)."""

from __future__ import annotations

from typing import Any, Mapping

import yaml

from tofnet.compiler.budget import budget_name_or_dict
from tofnet.core.network import Network
from tofnet.core.ports import InPort, OutPort
from tofnet.core.process import Process
from tofnet.errors import TofnetError
from tofnet.io.spec_data import Spec
from tofnet.units import seconds


def type_name_of(process: Process) -> str:
    """How a spec names the type of ``process``: the class name for tofnet's own (unless another class
    has that name) and for classes a script defines, else ``package.module:ClassName`` (importable in
    a new process)."""
    cls = type(process)
    own = cls.__module__.startswith("tofnet.processes") and Process.ambiguity(cls.__name__) is None
    if own or cls.__module__ in ("__main__", "__mp_main__"):
        return cls.__name__
    return f"{cls.__module__}:{cls.__qualname__}"


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


def spec_to_dict(spec: Spec | Network, full: bool = False) -> dict[str, Any]:
    """A spec (or a bare network) as plain data, ready for YAML or JSON."""
    if isinstance(spec, Network):  # a bare network: no description, compile or backend keys
        return network_to_dict(spec, full=full)
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
