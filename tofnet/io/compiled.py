"""A compiled network as plain data (``tofnet compile --json``): the spec it was compiled from,
the budget, the patch option and the mapping onto cores, and back.

It lives with the spec reader and writer rather than in the compiler, which never reads files.
"""

from __future__ import annotations

from typing import Any, Mapping

from tofnet.compiler import CompiledNetwork, CoreAssignment, LayerMapping, Traffic
from tofnet.compiler.budget import Budget
from tofnet.io.spec import network_from_dict, patch_from_data
from tofnet.io.spec_writer import network_to_dict, patch_to_data

#: The ``format`` field of the data.
COMPILED_FORMAT = "tofnet-compiled/1"


def compiled_to_dict(compiled: CompiledNetwork) -> dict[str, Any]:
    """JSON-able: the network spec, budget, layers, cores and traffic."""
    return {"format": COMPILED_FORMAT, "summary": compiled.summary(),
            "network": network_to_dict(compiled.network, full=True), "budget": compiled.budget.to_dict(),
            "patch": patch_to_data(compiled.patch), "host": list(compiled.host),
            "layers": [layer.to_dict() for layer in compiled.layers],
            "cores": [core.to_dict() for core in compiled.cores],
            "traffic": [t.to_dict() for t in compiled.traffic]}


def compiled_from_dict(data: Mapping[str, Any], *, allow_import: Any = None) -> CompiledNetwork:
    """Rebuild from ``compiled_to_dict`` output (the network from its embedded spec; ``allow_import``:
    the modules its ``module:Class`` types may import, as for ``load_spec``)."""
    return CompiledNetwork(network=network_from_dict(data["network"], allow_import=allow_import),
                           budget=Budget.from_dict(data["budget"]),
                           layers=tuple(LayerMapping.from_dict(layer) for layer in data["layers"]),
                           cores=tuple(CoreAssignment.from_dict(core) for core in data["cores"]),
                           traffic=tuple(Traffic.from_dict(t) for t in data["traffic"]),
                           host=tuple(data["host"]), patch=patch_from_data(data.get("patch")))
