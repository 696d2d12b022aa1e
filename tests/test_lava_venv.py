"""The lava backend's own tests, run in a Python 3.10 venv from the main suite.

lava-nc 0.10 needs Python 3.10, so under any other interpreter tests/test_lava.py only checks
the one-line refusal. Where a Python 3.10 exists (``python3.10`` on PATH, or pyenv's), this test
makes a venv once (cached under ``~/.cache/tofnet-ci/lava-py310``), installs ``tofnet[lava,test]``
into it and runs tests/test_lava.py there against this checkout: so the README's one test
command covers the lava backend too. Without a Python 3.10 it skips, saying so.
"""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow
#: pip's words for a registry it cannot reach: then the test skips instead of failing.
OFFLINE = ("Could not find a version", "No matching distribution", "Temporary failure in name resolution",
           "Failed to establish a new connection", "Network is unreachable")


def python310() -> str | None:
    """An interpreter that runs as Python 3.10 (a pyenv shim may exist without one selected)."""
    root = os.environ.get("PYENV_ROOT", str(Path.home() / ".pyenv"))
    for candidate in [shutil.which("python3.10"), *sorted(glob.glob(f"{root}/versions/3.10*/bin/python"))]:
        if candidate and subprocess.run([candidate, "-c", "import sys; assert sys.version_info[:2] == (3, 10)"],
                                        capture_output=True).returncode == 0:
            return candidate
    return None


def test_the_lava_backend_tests_pass_under_python_310():
    if sys.version_info[:2] == (3, 10):
        pytest.skip("this is Python 3.10: tests/test_lava.py runs here directly")
    interpreter = python310()
    if interpreter is None:
        pytest.skip("no Python 3.10 (python3.10 on PATH or under pyenv): the lava backend needs it (docs/lava.md)")
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    venv = cache / "tofnet-ci" / "lava-py310"
    python = venv / "bin" / "python"
    if not python.exists():
        subprocess.run([interpreter, "-m", "venv", str(venv)], check=True, capture_output=True)
    install = subprocess.run([str(python), "-m", "pip", "install", "-q", f"{ROOT}[lava,test]"],
                             capture_output=True, text=True, timeout=1800)
    if install.returncode != 0:
        text = install.stdout + install.stderr
        if any(word in text for word in OFFLINE):
            pytest.skip(f"cannot install lava-nc into {venv}: {text.strip().splitlines()[-1]}")
        pytest.fail(f"pip install tofnet[lava,test] into {venv} failed:\n{text[-3000:]}")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run([str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_lava.py"],
                         cwd=ROOT, capture_output=True, text=True, timeout=1800, env=env)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    assert " passed" in run.stdout.strip().splitlines()[-1]
