"""The layout's promise: the *what* never imports the *how* (docs/architecture.md)."""

import subprocess
import sys

WHAT = ["tofnet", "tofnet.core", "tofnet.processes", "tofnet.networks", "tofnet.io.spec", "tofnet.io.safe_yaml",
        "tofnet.io.spec_writer", "tofnet.compiler"]


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
