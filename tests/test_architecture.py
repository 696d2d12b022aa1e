"""The layout's promise: the *what* never imports the *how* (DESIGN.md §3)."""

import subprocess
import sys

WHAT = ["tofnet", "tofnet.core", "tofnet.processes", "tofnet.networks", "tofnet.io.spec", "tofnet.compiler"]


def test_declarations_specs_and_compiler_import_no_backend_kernel_or_numba():
    code = ("import sys\n" + "".join(f"import {m}\n" for m in WHAT) +
            "print(sorted(m for m in sys.modules if m.startswith(('tofnet.backends', 'tofnet.kernels', "
            "'tofnet.sim', 'numba'))))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]"
