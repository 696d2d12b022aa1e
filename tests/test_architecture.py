"""The layout's promise: the *what* never imports the *how* (docs/architecture.md)."""

import subprocess
import sys

WHAT = ["tofnet", "tofnet.core", "tofnet.processes", "tofnet.networks", "tofnet.io.spec", "tofnet.io.safe_yaml",
        "tofnet.io.spec_writer", "tofnet.io.spec_data", "tofnet.compiler"]


def test_declarations_specs_and_compiler_import_no_backend_kernel_or_numba():
    code = ("import sys\n" + "".join(f"import {m}\n" for m in WHAT) +
            "print(sorted(m for m in sys.modules if m.startswith(('tofnet.backends', 'tofnet.kernels', "
            "'tofnet.models', 'tofnet.sim', 'numba'))))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]"


def test_nothing_past_the_compiler_names_the_papers_processes():
    """Executors run any graph: only the fusion module (which recognises the paper's chain as an
    optimisation) and each process's own models may name a process type."""
    from pathlib import Path
    import tofnet
    root = Path(tofnet.__file__).parent
    names = ("InputProcess", "TimeOfTravelProcess", "DepthProcess", "VelocityProcess")
    allowed = {"fusion.py"}
    for path in sorted((root / "backends").glob("*.py")) + sorted((root / "compiler").glob("*.py")):
        if path.name in allowed:
            continue
        text = path.read_text()
        assert not any(name in text for name in names), f"{path.name} names one of the paper's processes"


# --- the import graph: layers and cycles ------------------------------------------------------------------------

#: tofnet's layers, lowest first: a module may import its own layer and those below, never above.
#: ``tofnet`` is the package's ``__init__`` (a facade over core, processes and networks).
LAYERS = (
    {"errors", "events", "units", "numba_cache", "machine", "pacing"},
    {"core", "kernels", "monitor", "fuzzing_checks"},
    {"compiler"},
    {"io"},
    {"processes", "sim"},
    {"networks", "tofnet"},
    {"models"},
    {"backends"},
    {"session"},
    {"api", "eval", "conformance", "testing", "testing_datasets", "live", "live_view", "live_stats"},
    {"warmup", "batch", "fuzzing_formats", "fuzzing_storage", "fuzzing_sessions"},
    {"cli", "fuzzing_trust", "fuzzing_outputs"},
    {"fuzzing"},
    {"__main__"},
)
#: Imports that still run up a layer, each with what removes it (no new entry without one).
UPWARD_KNOWN: set[tuple[str, str]] = set()
#: Cycles still in the tree, each with what removes it (none today: keep it so).
CYCLES_KNOWN: list[set[str]] = []


def _import_graph() -> dict[str, set[str]]:
    """Module -> the tofnet modules it imports: function-level and ``if TYPE_CHECKING:`` imports too
    (a type-only import still ties the two files together: a circle of them is a circle)."""
    import ast
    from pathlib import Path
    import tofnet

    root = Path(tofnet.__file__).parent
    modules = {}
    for path in root.rglob("*.py"):
        parts = ["tofnet", *path.relative_to(root).with_suffix("").parts]
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path

    def imported(path: Path) -> set[str]:
        found: set[str] = set()

        class Visitor(ast.NodeVisitor):
            def visit_Import(self, node: ast.Import) -> None:
                found.update(a.name for a in node.names if a.name.startswith("tofnet"))

            def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
                assert node.level == 0, f"{path}:{node.lineno}: a relative import; tofnet imports absolutely"
                if node.module and node.module.startswith("tofnet"):
                    for alias in node.names:
                        full = f"{node.module}.{alias.name}"
                        found.add(full if full in modules else node.module)

        Visitor().visit(ast.parse(path.read_text()))
        return found

    return {name: {m for m in imported(path) if m in modules and m != name} for name, path in modules.items()}


def _layer(module: str) -> int:
    parts = module.split(".")
    top = parts[1] if len(parts) > 1 else "tofnet"
    for i, layer in enumerate(LAYERS):
        if top in layer:
            return i
    raise AssertionError(f"{module}: its package {top!r} is in no layer of LAYERS; add it where it belongs")


def test_no_import_runs_up_a_layer():
    graph = _import_graph()
    upward = {(a, b) for a, targets in graph.items() for b in targets if _layer(b) > _layer(a)}
    assert upward - UPWARD_KNOWN == set(), "imports that run up a layer (docs/architecture.md)"
    assert UPWARD_KNOWN - upward == set(), "a known upward import is gone: remove it from UPWARD_KNOWN"


def test_no_import_cycle_beyond_the_known_ones():
    import networkx as nx

    graph = nx.DiGraph([(a, b) for a, targets in _import_graph().items() for b in targets])
    cycles = [set(c) for c in nx.strongly_connected_components(graph) if len(c) > 1]
    assert [c for c in cycles if c not in CYCLES_KNOWN] == []
    assert [c for c in CYCLES_KNOWN if c not in cycles] == [], "a known cycle is gone: remove it from CYCLES_KNOWN"
