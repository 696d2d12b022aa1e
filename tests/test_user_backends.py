"""A user's own backend, built as docs/backends.md and docs/extending.md say: it computes what it
declares, runs wherever a built-in does (or says in one line why not), and a broken plug-in names
itself without taking the other backends down."""

import numpy as np
import pytest

from tofnet.backends.base import Backend, RunResult
from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.backends.local import LocalBackend
from tofnet.backends.registry import available_backends, get_backend
from tofnet.cli import main
from tofnet.conformance import CASES, run_suite
from tofnet.errors import BackendError


@pytest.fixture(scope="module")
def scene():
    return next(c for c in CASES if c.name == "texture-blobs").build()


class MyFixedBackend(LocalBackend):  # the docs' recipe: subclass LocalBackend, say the family
    name = "myfixed"
    arithmetic = "fixed"
    family = "fixed"


class RunOnlyBackend(Backend):  # the docs' smallest backend: only ``run``, no streams
    name = "run-only"
    arithmetic = "fixed"
    family = "fixed"

    def run(self, compiled, recording, **options):
        return FixedBackend().run(compiled, recording, **options)


def test_a_local_backend_that_says_fixed_computes_in_fixed_point(scene):
    """It ran the float path before (depths byte-equal to float's) while the suite against the
    reference passed it."""
    mine = MyFixedBackend().run(scene.network, scene.recording)
    assert len(mine.depth) > 100
    assert mine.depth.tobytes() == FixedBackend().run(scene.network, scene.recording).depth.tobytes()
    assert mine.depth.tobytes() != FloatBackend().run(scene.network, scene.recording).depth.tobytes()


def test_a_backend_without_streams_runs_a_file_and_is_not_applicable_to_sessions(registered, scene, tmp_path):
    from tofnet.api import run_source
    from tofnet.io.in_memory import RecordingSource

    registered("run-only", RunOnlyBackend)
    source = RecordingSource(scene.recording, "npy", tmp_path / "scene.npy")
    result, _ = run_source(source, scene.network, backend="run-only")  # tofnet run's road: streams before
    assert result.depth.tobytes() == FixedBackend().run(scene.network, scene.recording).depth.tobytes()
    results = run_suite("run-only", "fixed", cases=["variables", "edge+u"])
    sessions = [r for r in results if r.case.startswith("variables")]
    assert len(sessions) >= 3 and all(not r.applies and r.ok and "offers no streams" in r.first for r in sessions)
    assert [(r.case, r.applies, r.ok) for r in results if r not in sessions] == [("edge+u", True, True)]
    np.save(tmp_path / "events.npy", scene.recording.events)
    camera = ["--intrinsics", "200,200,12,8", "--velocity", "0.5,0,0", "--quiet"]
    for name in ("run-only", "fixed"):  # tofnet run reads the file in packets for a stream: whole for run-only
        assert main(["run", str(tmp_path / "events.npy"), "--backend", name, "--out", str(tmp_path / f"{name}.npz"),
                     *camera]) == 0
    depth = np.load(tmp_path / "run-only.npz")["z"]
    assert len(depth) > 100 and depth.tobytes() == np.load(tmp_path / "fixed.npz")["z"].tobytes()


def test_a_backend_that_cannot_load_is_one_line_and_the_others_still_run(registered, capsys):
    registered("broken", "tofnet_no_such_module_zz:Backend")
    with pytest.raises(BackendError, match="cannot load backend 'tofnet_no_such_module_zz:Backend': "
                                           "ModuleNotFoundError") as err:
        get_backend("broken")
    assert "\n" not in str(err.value)
    assert main(["conformance", "--list"]) == 0
    listed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("backend ")]
    assert [line.split()[1] for line in listed] == available_backends()
    assert "cannot load backend 'tofnet_no_such_module_zz" in next(line for line in listed if line.split()[1] == "broken")
    assert main(["conformance", "--backend", "broken", "--case", "edge+u"]) == 2  # asked for: one line, no table
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and "ModuleNotFoundError" in captured.err


def test_a_broken_backend_among_all_is_counted_and_the_rest_run(registered, capsys, monkeypatch, tmp_path):
    registered("broken", "tofnet_no_such_module_zz:Backend")
    monkeypatch.setattr("tofnet.backends.registry.available_backends", lambda optional=False: ["broken", "float"])
    assert main(["conformance", "--case", "edge+u", "--json", str(tmp_path / "outcomes.json")]) == 1
    out = capsys.readouterr()
    assert "== broken: cannot load backend " in out.out and "== float vs reference" in out.out
    assert out.err.splitlines()[-1] == "tofnet conformance: 1 backend(s) could not be loaded: broken"
    import json
    outcomes = json.loads((tmp_path / "outcomes.json").read_text())
    assert outcomes[0]["backend"] == "broken" and "ModuleNotFoundError" in outcomes[0]["error"]
    assert [o["case"] for o in outcomes[1:]] == ["edge+u"] and outcomes[1]["ok"]


class RebuiltBackend(Backend):  # docs/backends.md's recipe for a result of one's own: ``RunResult.of``
    name = "rebuilt"
    arithmetic = "fixed"
    family = "fixed"

    def run(self, compiled, recording, **options):
        ran = FixedBackend().run(compiled, recording, **options)
        return RunResult.of(compiled, self.name, ran.outputs, ran.counts, steps=ran.steps, t0_us=ran.t0_us,
                            timestep_us=ran.timestep_us, latency=ran.latency)


def test_a_result_built_with_run_result_of_reads_as_the_built_ins(scene):
    """A result built positionally as the docs implied (no ``declared``) said 0 events in and accepted
    in the summary, and one without ``payloads`` wrote its depth under another name; ``RunResult.of``
    derives both from the network."""
    mine, fixed = (b.run(scene.network, scene.recording) for b in (RebuiltBackend(), FixedBackend()))
    assert mine.payloads == fixed.payloads and mine.declared == fixed.declared
    assert mine.events_in == fixed.events_in == len(scene.recording.events) and mine.accepted == fixed.accepted > 0
    assert mine.facts() == fixed.facts() and mine.depth.tobytes() == fixed.depth.tobytes()


def test_a_result_without_payloads_or_declared_counts_is_refused(scene):
    ran = FixedBackend().run(scene.network, scene.recording)
    positional = (ran.backend, ran.outputs, ran.counts, ran.steps, ran.t0_us, ran.timestep_us, ran.latency)
    with pytest.raises(BackendError, match=r"no payload for \[\], no declared counts for \['input', "):
        RunResult(*positional, ran.payloads)  # one line for a field left out, not a TypeError's traceback
    with pytest.raises(BackendError) as err:
        RunResult(*positional, {}, {})
    assert "\n" not in str(err.value) and "RunResult.of(network, ...)" in str(err.value)
    assert "no payload for ['depth.depth'], no declared counts for ['input', 'time_of_travel', 'depth', " \
           "'velocity']" in str(err.value)


def test_the_workers_check_is_not_applicable_to_a_backend_that_takes_no_workers(registered, capsys):
    """It said FAIL (``backend 'run-only' does not take the options ['workers']``) before: a backend
    declares ``"bands"`` in its capabilities when it takes ``workers=N``."""
    from tofnet.conformance.workers import check_workers
    registered("run-only", RunOnlyBackend)
    assert "bands" not in RunOnlyBackend.capabilities and "bands" in MyFixedBackend.capabilities
    (row,) = check_workers("run-only", (1, 2), ["edge+u"])
    assert (row.applies, row.ok, row.mode) == (False, True, "bands")
    assert row.first == "n/a: backend 'run-only' takes no workers (Backend.capabilities has no 'bands')"
    assert main(["conformance", "--backend", "run-only", "--workers", "1,2", "--case", "edge+u"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[2].split()[:3] == ["edge+u", "bands", "n/a"] and out[3].startswith("1 cases: 0 passed, 1 not applicable")
