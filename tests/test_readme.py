"""The README's command blocks (```sh) run in order in a fresh folder, as a newcomer types them,
and then its Python blocks, one after the other in one interpreter, on the files they made.

Installing tofnet and running the test suite are left out (this test is part of that suite and
runs on the tree itself): ``tofnet`` is this tree's (``python -m tofnet`` with the tree on
``PYTHONPATH`` when no console script is installed), and ``examples/`` is the repository's, as
in a clone, with an empty numba cache (a fresh install): the first command, ``tofnet warmup``, must
say it compiles the kernels, and no later one compile any. Every command must succeed without a
traceback; the files they write are checked.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from optional import optional

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def command_lines(text: str) -> list[str]:
    """Every command line of the README's ``sh`` blocks, in order, comments cut."""
    lines = []
    for block in re.findall(r"^```sh\n(.*?)^```", text, flags=re.S | re.M):
        for line in block.splitlines():
            line = line.split(" #", 1)[0].strip()
            if line and not line.startswith("#"):
                lines.append(line)
    return lines


def python_blocks(text: str) -> list[str]:
    """The README's ``python`` blocks, in order."""
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def commands(line: str) -> list[list[str]]:
    """The commands of one line (``a && b``) this test runs: not ``pip install`` nor the test suite."""
    out = []
    for part in line.split("&&"):
        argv = shlex.split(part)
        if argv[:2] == ["pip", "install"] or argv[:3] == ["python", "-m", "pytest"]:
            continue
        out.append(argv)
    return out


def tofnet_command() -> list[str]:
    script = shutil.which("tofnet")
    return [script] if script else [sys.executable, "-m", "tofnet"]


def test_readme_blocks_are_found_and_name_real_subcommands():
    lines = command_lines((ROOT / "README.md").read_text(encoding="utf-8"))
    from tofnet.cli import SUBCOMMANDS
    argvs = [argv for line in lines for argv in commands(line)]
    assert len(argvs) >= 10 and all(argv[0] == "tofnet" and argv[1] in SUBCOMMANDS for argv in argvs)
    assert commands('pip install ".[test]" && python -m pytest -q') == []


def test_every_readme_command_runs_in_order_in_a_fresh_folder(tmp_path):
    optional("faery"), optional("h5py")  # the README's blocks come after its second command, which installs them
    lines = command_lines((ROOT / "README.md").read_text(encoding="utf-8"))
    (tmp_path / "examples").symlink_to(ROOT / "examples")  # a clone has them
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
               NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))  # a fresh install: no kernel compiled yet
    printed, announced = {}, []
    for line in lines:
        for argv in commands(line):
            done = subprocess.run(tofnet_command() + argv[1:], cwd=tmp_path, env=env, capture_output=True, text=True,
                                  timeout=600)
            assert done.returncode == 0, f"{' '.join(argv)} exited {done.returncode}:\n{done.stderr[-2000:]}"
            assert "Traceback" not in done.stderr, f"{' '.join(argv)}:\n{done.stderr[-2000:]}"
            printed[" ".join(argv)] = done.stdout
            if "compiling kernels, first run only" in done.stderr:
                announced.append(" ".join(argv))
    # the README's first command compiles every kernel, and says so (its own wait, on stdout, not a run's
    # "compiling kernels" line); no later one waits for a compile
    assert announced == [], announced
    assert printed["tofnet warmup"].startswith("warming up every kernel tofnet runs (1-3 min")
    assert "kernels compiled in" in printed["tofnet warmup"]
    from tofnet.io.depth import read_depth

    depth, _ = read_depth(tmp_path / "depth.npz")
    improved, _ = read_depth(tmp_path / "depth_improved.npz")
    window, _ = read_depth(tmp_path / "window.npz")
    constant, _ = read_depth(tmp_path / "constant.npz")
    assert len(depth) > 1000 and len(improved) > 1000 and len(constant) > 1000
    assert 0 < len(window) < len(constant)  # 0.2 s of the 0.5 s
    assert all(0.35 < np.median(d["z"]) < 3.0 for d in (depth, improved, constant))  # the desk scene's depths
    assert (tmp_path / "tofnet-demo" / "figures" / "compare.png").stat().st_size > 10_000
    assert len(list((tmp_path / "figs").glob("*.png"))) >= 4
    assert list((tmp_path / "maps").iterdir()) and (tmp_path / "cloud.ply").read_bytes().startswith(b"ply")
    said = "\n".join(printed.values())
    assert "rel error" in said and "pixels used    x 0..239, y 0..179" in said
    assert "cores" in printed["tofnet compile examples/paper_240x180.yaml"]
    assert " 0 failed" in printed["tofnet conformance --backend multiproc --case edge"]
    assert "done in" in printed["tofnet warmup"]

    script = "\n".join(python_blocks((ROOT / "README.md").read_text(encoding="utf-8")))
    script += "\nprint('estimates', len(result.outputs['depth2.depth']))"
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, f"the README's Python blocks:\n{done.stderr[-2000:]}"
    assert int(done.stdout.split()[-1]) > 1000
