"""A batch's outputs (issue 27, items 2 and 4): checked before any task runs, never a folder
of other files nor an input, ``--force`` for an earlier batch's folder, and resume keyed
by the content of the inputs. The refusals come before a cluster is started, so most of
these tests need no Dask; the end-to-end resume test is in test_batch_dask.py."""

import errno
import json
import os

import numpy as np
import pytest

from tofnet.batch import expand, load_plan
from tofnet.batch.outputs import check_batch_output, fingerprint, mark_output, plan_inputs
from tofnet.errors import TofnetError
from tofnet.events import make_events
from tofnet.io.guard import MANIFEST

from optional import optional
from test_reliability_full_disk import tmpfs
from test_reliability_outputs import one_line_error


@pytest.fixture
def folder(tmp_path):
    np.save(tmp_path / "a.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 0]))
    return tmp_path


def plan(folder, output="out", extra=""):
    path = folder / "plan.yaml"
    path.write_text(f"name: t\noutput: {output}\nrecordings: [a.npy]\ngrid:\n  distance: [1, 2]\n{extra}")
    return path


@pytest.fixture
def no_cluster(monkeypatch):
    """Fails the test if a cluster is started: the outputs must be refused before."""
    optional("distributed")
    from tofnet.batch import runner

    def refuse(*args, **kwargs):
        raise AssertionError("a cluster was started before the output was checked")
    monkeypatch.setattr(runner, "_connect", refuse)


def test_an_output_folder_of_other_files_is_never_used(folder, capsys, no_cluster):
    (folder / "mine").mkdir()
    (folder / "mine" / "results.csv").write_text("my own table")
    (folder / "mine" / "plot.png").write_bytes(b"my own figure")
    path = plan(folder, "mine")
    for force in ([], ["--force"]):
        err = one_line_error(capsys, ["batch", str(path), *force])
        assert "which tofnet did not write" in err
    assert (folder / "mine" / "results.csv").read_text() == "my own table"
    assert sorted(os.listdir(folder / "mine")) == ["plot.png", "results.csv"]


def test_the_plans_own_folder_is_never_an_output(folder, capsys, no_cluster):
    err = one_line_error(capsys, ["batch", str(plan(folder, ".")), "--force"])
    assert "holding the input" in err or "which tofnet did not write" in err
    assert sorted(os.listdir(folder)) == ["a.npy", "plan.yaml"]


def test_a_scenario_cache_of_other_files_is_never_filled(folder, capsys, no_cluster):
    """A plan from someone else may name any folder of yours as its cache; simulations go only where the
    folder is empty, new, or holds tofnet's scenarios."""
    mine = folder / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("precious")
    path = folder / "plan.yaml"
    path.write_text(f"output: out\ncache: {mine}\nrecordings: [{{scenario: slider, duration: 0.05}}]\n")
    err = one_line_error(capsys, ["batch", str(path)])
    assert "cache is a folder holding 'notes.txt', which is not a simulated scenario" in err
    assert sorted(os.listdir(mine)) == ["notes.txt"] and not (folder / "out").exists()
    (mine / "notes.txt").unlink()
    (mine / "slider-x").mkdir()
    (mine / "slider-x" / "scenario.json").write_text("{}")  # an earlier batch's scenario
    (mine / ".slider-y.tmp-1-ab").mkdir()  # a simulation killed half-way
    check_batch_output(load_plan(path))


def test_an_earlier_batchs_folder_needs_force_or_resume(folder, capsys, no_cluster):
    loaded = load_plan(plan(folder))
    mark_output(loaded)  # what a batch does before its first task
    assert (folder / "out" / MANIFEST).is_file()
    (folder / "out" / "results.csv").write_text("earlier")
    err = one_line_error(capsys, ["batch", str(folder / "plan.yaml")])
    assert "exists; pass --resume to continue it, or --force" in err
    check_batch_output(loaded, force=True)
    check_batch_output(loaded, resume=True)
    (folder / "out" / "notes.txt").write_text("added by hand")
    with pytest.raises(TofnetError, match="'notes.txt', which tofnet did not write"):
        check_batch_output(loaded, force=True)


def test_inputs_are_protected_from_the_batch(folder, no_cluster):
    (folder / "calib.txt").write_text("200 200 120 90\n")
    loaded = load_plan(plan(folder, "out", "calib: calib.txt\n"))
    assert {p.name for p in plan_inputs(loaded)} >= {"plan.yaml", "a.npy", "calib.txt"}
    mark_output(loaded)
    (folder / "out" / "tasks").mkdir()
    os.replace(folder / "a.npy", folder / "out" / "tasks" / "a.npy")  # an input inside an earlier batch's folder
    (folder / "plan.yaml").write_text("output: out\nrecordings: [out/tasks/a.npy]\n")
    with pytest.raises(TofnetError, match="would replace a folder holding the input .*a.npy"):
        check_batch_output(load_plan(folder / "plan.yaml"), force=True)


def test_a_read_only_output_is_refused_before_any_task(folder, capsys, no_cluster, monkeypatch):
    from tofnet.io import files

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")
    monkeypatch.setattr(files.tempfile, "mkstemp", read_only)
    err = one_line_error(capsys, ["batch", str(plan(folder))])
    assert "cannot write in this folder: Read-only file system" in err


def test_a_read_only_file_system_is_refused_before_any_task(folder, capsys, no_cluster):
    with tmpfs("1m", "ro") as read_only:
        err = one_line_error(capsys, ["batch", str(plan(folder)), "--out", str(read_only / "results")])
        assert str(read_only) in err and ("not writable" in err or "Read-only file system" in err)


def test_fingerprints_follow_the_content_not_the_path(folder):
    big = folder / "big.npy"
    events = make_events(np.arange(100_000) * 10, np.zeros(100_000, int), np.zeros(100_000, int),
                         np.ones(100_000, int))
    np.save(big, events)
    (folder / "plan.yaml").write_text("output: out\nrecordings: [big.npy]\n")
    task = expand(load_plan(folder / "plan.yaml"))[0]
    first, whole = fingerprint(task), fingerprint(task, "full")
    assert first == fingerprint(task) and first != whole
    stat = os.stat(big)
    data = bytearray(big.read_bytes())
    data[len(data) // 2] ^= 0xFF  # same size, same mtime below: only the content says it changed
    big.write_bytes(bytes(data))
    os.utime(big, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert fingerprint(task) != first and fingerprint(task, "full") != whole
    sampled, whole = fingerprint(task), fingerprint(task, "full")
    data[len(data) // 3] ^= 0xFF  # outside the three samples: only a full hash sees it
    big.write_bytes(bytes(data))
    os.utime(big, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert fingerprint(task) == sampled and fingerprint(task, "full") != whole
    os.utime(big, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))  # touched: the mtime is in both
    assert fingerprint(task) != sampled


def test_resume_reruns_a_task_whose_recording_changed(folder):
    from dataclasses import replace

    from tofnet.batch.worker import ROW_FILE, is_complete

    (folder / "plan.yaml").write_text("output: out\nrecordings: [a.npy]\nkeep: [metrics]\n")
    task = expand(load_plan(folder / "plan.yaml"))[0]
    task = replace(task, fingerprint=fingerprint(task))
    os.makedirs(task.folder)
    row = {"task": 0, "task_id": task.task_id, "status": "ok", "keep": ["metrics"], "fingerprint": task.fingerprint}
    (folder / "out" / "tasks" / task.task_id / ROW_FILE).write_text(json.dumps(row))
    assert is_complete(task) is not None
    np.save(folder / "a.npy", make_events([0, 1000], [1, 3], [1, 1], [1, 0]))  # same path, other events
    assert is_complete(replace(task, fingerprint=fingerprint(task))) is None
    for text in ("[" * 100_000, '{"task": ' + "1" * 5000 + "}", "[1, 2]"):  # traceback (RecursionError, ...)
        (folder / "out" / "tasks" / task.task_id / ROW_FILE).write_text(text)
        assert is_complete(task) is None  # not a row: the task runs again


def test_a_full_disk_while_writing_the_table_is_one_line_and_no_file(tmp_path, monkeypatch):
    from tofnet.batch.table import write_table
    from tofnet.io import files

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(files.os, "fsync", full)
    with pytest.raises(TofnetError) as caught:
        write_table([{"task": 0, "task_id": "a", "status": "ok"}], [], tmp_path)
    assert str(caught.value) == f"{tmp_path / 'results.csv'}: cannot write: No space left on device"
    assert os.listdir(tmp_path) == []
