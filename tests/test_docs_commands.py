"""The command blocks of docs/*.md that a reader pastes run as written, in a fresh folder.

Each page's ``tofnet`` lines run in order in a folder of their own (with ``examples/`` as in a
clone, and the README's ``rec/``, ``tofnet simulate slider rec/ --duration 0.5``, where a page
works on it), through ``tofnet.cli.main`` in this process (the README test runs the console
script; here the imports are paid once). Every command must exit 0; a few outputs are checked.

Not run, each for its reason (``EXCLUDED``; a new command line in the docs must be run or listed
there, ``test_every_docs_command_is_run_or_excluded_with_a_reason``):

- ``pip install``: installing is the reader's step; the suite runs on the tree.
- ``python benchmarks/...`` (accuracy, performance, time_surface): minutes each; they are the
  measurements, not examples.
- ``tofnet demo`` (time_surface.md): ~15 s; the README test runs it.
- ``tofnet conformance`` over every case (backends.md): 8-60 s; tests/test_conformance.py and
  tests/test_multiproc*.py run the cases; the two quick lines of that block run here.
- ``tofnet batch`` runs (batch.md): the example plan is 40 tasks on a Dask cluster (minutes);
  tests/test_batch_*.py run small plans; its ``--check`` line runs here. ``dask scheduler`` /
  ``dask worker`` start a cluster.
- formats.md's datasets block: tests/test_sequences_other.py runs it on its synthetic folders.
- live.md's ``--camera`` line: it needs an event camera; tests/test_live.py checks the line said
  without one and the camera's packets. Its replays run on the ``rec.raw`` they name, written
  here as a camera writes it (``prophesee_raw``), and its Python block runs too.

Marked ``slow``: about 30 s once the kernels are compiled.
"""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest

from tofnet.cli import SUBCOMMANDS, main

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: (page, start of the command line) -> why it does not run here.
EXCLUDED = {
    ("*", "pip install"): "installing is the reader's step",
    ("accuracy.md", "python benchmarks/"): "benchmark: minutes",
    ("performance.md", "python benchmarks/"): "benchmark: minutes",
    ("time_surface.md", "python benchmarks/"): "benchmark: minutes",
    ("time_surface.md", "tofnet demo"): "~15 s; the README test runs it",
    ("backends.md", "tofnet conformance --backend multiproc --against fixed"): "every case; test_multiproc*",
    ("batch.md", "tofnet batch examples/batch/refractory_sweep.yaml --workers"): "40 tasks on Dask: minutes",
    ("batch.md", "tofnet batch examples/batch/refractory_sweep.yaml --resume"): "runs the plan's tasks",
    ("batch.md", "tofnet batch examples/batch/refractory_sweep.yaml --force"): "runs the plan's tasks",
    ("batch.md", "tofnet batch plan.yaml --scheduler"): "needs a Dask cluster",
    ("batch.md", "dask "): "starts a Dask cluster",
    ("formats.md", ""): "tests/test_sequences_other.py runs the datasets block",
    ("live.md", "tofnet live --camera"): "needs an event camera; tests/test_live.py: no camera, its packets",
}
#: Lines excluded by their exact text (a prefix would also match the lines that run).
EXCLUDED_LINES = {("backends.md", "tofnet conformance"): "all 62 cases x every backend: ~60 s"}
#: Pages that work on the README's rec/.
NEEDS_REC = {"time_surface.md", "spec.md"}
#: Pages that work on a Prophesee ``rec.raw``.
NEEDS_RAW = {"live.md"}


def command_lines(text: str) -> list[str]:
    """The command lines of a page's fenced blocks (untagged or ``sh``), comments cut: lines that
    start a ``tofnet`` subcommand, ``python``, ``pip`` or ``dask`` (not printed output)."""
    lines, fence = [], None
    for raw in text.splitlines():
        if raw.startswith("```"):
            fence = raw[3:].strip() if fence is None else None  # an opening fence's language, or closed
            continue
        if fence in ("", "sh"):
            line = raw.split(" #", 1)[0].strip()
            words = line.split()
            if words and ((words[0] == "tofnet" and len(words) > 1 and words[1] in SUBCOMMANDS) or
                          words[0] in ("python", "pip", "dask")):
                lines.append(line)
    return lines


def excluded(page: str, line: str) -> str | None:
    """Why ``line`` of ``page`` does not run here, or None."""
    if (page, line) in EXCLUDED_LINES:
        return EXCLUDED_LINES[(page, line)]
    for (where, start), why in EXCLUDED.items():
        if where in ("*", page) and line.startswith(start):
            return why
    return None


def pages() -> list[str]:
    return sorted(p.name for p in DOCS.glob("*.md"))


def runnable(page: str) -> list[str]:
    return [line for line in command_lines((DOCS / page).read_text(encoding="utf-8")) if excluded(page, line) is None]


RUN = [page for page in pages() if runnable(page)]


def test_every_docs_command_is_run_or_excluded_with_a_reason():
    every = {page: command_lines((DOCS / page).read_text(encoding="utf-8")) for page in pages()}
    assert sum(map(len, every.values())) >= 30
    for line in (line for lines in every.values() for line in lines):
        words = shlex.split(line)
        assert words[0] != "tofnet" or words[1] in SUBCOMMANDS, line
    assert RUN == ["backends.md", "batch.md", "evaluation.md", "live.md", "simulator.md", "spec.md", "time_surface.md"]
    # Every exclusion still names a line of the docs (a stale one would hide nothing).
    for (where, start) in [*EXCLUDED, *EXCLUDED_LINES]:
        hit = [line for page, lines in every.items() if where in ("*", page) for line in lines
               if line.startswith(start)]
        assert hit, (where, start)


@pytest.fixture(scope="module")
def readme_rec(tmp_path_factory):
    """The README's first command: ``tofnet simulate slider rec/ --duration 0.5``."""
    folder = tmp_path_factory.mktemp("readme")
    assert main(["simulate", "slider", str(folder / "rec"), "--duration", "0.5"]) == 0
    return folder / "rec"


@pytest.fixture(scope="module")
def prophesee_raw(tmp_path_factory):
    """live.md's ``rec.raw`` as a Prophesee camera writes it: EVT3, 1280x720, no calibration beside it;
    2.5 s of a texture sliding across the middle of the sensor (584,000 events)."""
    pytest.importorskip("faery", reason='needs faery: pip install "tofnet[formats]" (writes the .raw)')
    from types import SimpleNamespace

    from tofnet.io.prophesee_write import write_prophesee
    from tofnet.testing import moving_pattern

    events = moving_pattern((160, 120), (60.0, 20.0), 2_500_000, sample_us=500)
    events["x"] += 560
    events["y"] += 300
    path = tmp_path_factory.mktemp("live") / "rec.raw"
    write_prophesee(path, [events], SimpleNamespace(sensor_size=(1280, 720)), "evt3")
    return path


@pytest.mark.slow
@pytest.mark.parametrize("page", RUN)
def test_a_docs_page_s_commands_run_as_written(page, tmp_path, monkeypatch, capsys, request):
    pytest.importorskip("faery", reason='needs faery: pip install "tofnet[formats]" (simulate to .aedat4)') \
        if page == "simulator.md" else None
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    if page in NEEDS_REC:
        shutil.copytree(request.getfixturevalue("readme_rec"), tmp_path / "rec")
    if page in NEEDS_RAW:
        shutil.copy(request.getfixturevalue("prophesee_raw"), tmp_path / "rec.raw")
        for name in ("DISPLAY", "WAYLAND_DISPLAY"):  # a window would wait for the reader
            monkeypatch.delenv(name, raising=False)
    monkeypatch.chdir(tmp_path)
    printed = {}
    for line in runnable(page):
        capsys.readouterr()
        code = main(shlex.split(line)[1:])
        out = capsys.readouterr()
        assert code == 0, f"{page}: {line} exited {code}: {out.err[-1500:]}"
        printed[line] = out.out
    CHECKS[page](tmp_path, printed)


def _depth(path: Path) -> np.ndarray:
    from tofnet.io.depth import read_depth
    return read_depth(path)[0]


def _backends(folder: Path, printed: dict) -> None:
    import re
    ran = printed["tofnet conformance --backend fixed --case patch --case speed-4bit-15"]
    assert re.search(r"\b(\d+) cases: \1 passed, 0 failed \(fixed vs reference", ran) and "speed-4bit-15" in ran
    assert "speed-4bit-15" in printed["tofnet conformance --list"]


def _batch(folder: Path, printed: dict) -> None:
    listed = printed["tofnet batch examples/batch/refractory_sweep.yaml --check"]
    assert "10 recordings x 1 networks x 4 grid points = 40 tasks" in listed
    assert "slider.paper.refractory=60ms" in listed


def _evaluation(folder: Path, printed: dict) -> None:
    import json
    assert len(_depth(folder / "depth.npz")) > 1000
    assert json.loads((folder / "metrics.json").read_text())  # the metrics, as JSON
    assert len(list((folder / "figures").glob("*.png"))) >= 4 and (folder / "map.png").stat().st_size > 10_000


def _live(folder: Path, printed: dict) -> None:
    import contextlib
    import io
    import re

    whole, window = (printed[line] for line in runnable("live.md"))
    assert "replay at 1x, 1280x720 px" in whole and "events in           583,956" in whole
    assert "note           time window 2 s .. 5 s" in window and "PNG frames -> frames" in window
    assert sorted(folder.joinpath("frames").glob("depth-*.png"))
    # The Python block, as written, in the same folder.
    code = re.search(r"```python\n(.*?)```", (DOCS / "live.md").read_text(encoding="utf-8"), re.S).group(1)
    shown = io.StringIO()
    with contextlib.redirect_stdout(shown):
        exec(compile(code, "docs/live.md", "exec"), {})
    assert re.search(r"^events         583,956 in ", shown.getvalue(), re.M)


def _simulator(folder: Path, printed: dict) -> None:
    from tofnet.io import read_recording
    assert "slider" in printed["tofnet simulate --list"]
    assert (folder / "out" / "slider" / "events.txt").stat().st_size > 0 and (folder / "aa.json").exists()
    assert len(read_recording(folder / "rec.aedat4").events) > 1000


def _time_surface(folder: Path, printed: dict) -> None:
    improved, spec = _depth(folder / "depth.npz"), _depth(folder / "spec.npz")
    assert len(improved) > 1000 and improved.tobytes() == spec.tobytes()  # "the same network"
    assert "host" in printed["tofnet compile --estimator improved"]


def _spec(folder: Path, printed: dict) -> None:
    import json
    first, distance2 = _depth(folder / "first.npz"), _depth(folder / "distance2.npz")
    assert len(first) > 1000 and len(distance2) > 1000
    with np.load(folder / "first.npz") as saved:  # the summary the run stored: a burst's later events not fitted
        summary = json.loads(str(saved["summary_json"]))
    counts = summary["counts"]["time_surface"]
    # first events only: on this slider 74 % of the events end as a burst's (39 % with the default K = 4),
    # and 17 % are answered (42 %)
    assert counts["burst"] > 0.6 * counts["events_in"] and counts["emitted"] < 0.25 * counts["events_in"]


CHECKS = {"backends.md": _backends, "batch.md": _batch, "evaluation.md": _evaluation, "live.md": _live,
          "simulator.md": _simulator, "spec.md": _spec, "time_surface.md": _time_surface}
