"""Issue 11 regressions, outputs: checked before the run, atomic, never clobbering, never read back truncated."""

from __future__ import annotations

import errno
import importlib.util
import os

import numpy as np
import pytest

import tofnet.api
from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.events import DEPTH_DTYPE, make_events
from tofnet.io import files
from tofnet.io.depth import read_depth, write_depth
from tofnet.io.ecd import write_ecd
from tofnet.io.events import write_events_npy
from tofnet.io.recording import Intrinsics


@pytest.fixture
def folder(tmp_path):
    path = tmp_path / "rec"
    events = make_events([0, 1000, 2000], [1, 2, 3], [1, 1, 1], [1, 1, 1])
    write_ecd(path, events, intrinsics=Intrinsics(200.0, 200.0, 119.5, 89.5), times=[0.0, 1.0],
              positions=[[0, 0, 0], [0.5, 0, 0]], quaternions=[[0, 0, 0, 1], [0, 0, 0, 1]], sensor_size=(240, 180))
    return path


@pytest.fixture
def no_run(monkeypatch):
    """Fails the test if the network is run: the outputs must be refused before."""
    def refuse(*args, **kwargs):
        raise AssertionError("the network ran before the outputs were checked")
    monkeypatch.setattr(tofnet.api, "run", refuse)


def one_line_error(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def _depth(n: int = 3) -> np.ndarray:
    depth = np.zeros(n, dtype=DEPTH_DTYPE)
    depth["t"], depth["x"], depth["z"], depth["step"] = np.arange(n) * 1000 + 2000, np.arange(n), 1.5, np.arange(n)
    return depth


# ---------------------------------------------------------------- checked before the run

def test_unwritable_outputs_are_refused_before_the_run(folder, tmp_path, capsys, no_run):
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_folder").mkdir()
    run = ["run", str(folder), "--quiet"]
    assert "is a folder" in one_line_error(capsys, [*run, "--out", str(tmp_path / "a_folder")])
    assert "which is a file" in one_line_error(capsys, [*run, "--out", str(tmp_path / "a_file" / "d.npz")])
    assert "which is a file" in one_line_error(capsys, [*run, "--json", str(tmp_path / "a_file" / "x" / "s.json"),
                                                        "--out", str(tmp_path / "d.npz")])
    assert "must be a .npz or .csv" in one_line_error(capsys, [*run, "--out", str(tmp_path / "d.txt")])
    assert "name the same file" in one_line_error(capsys, [*run, "--out", str(tmp_path / "d.npz"),
                                                           "--json", str(tmp_path / "d.npz")])
    assert "name the same file" in one_line_error(capsys, [*run, "--out", str(tmp_path / "d.npz"), "--record-tot",
                                                           "--json", str(tmp_path / "d_tot.npz")])


def test_a_folder_that_cannot_be_written_is_refused_before_the_run(folder, tmp_path, capsys, no_run, monkeypatch):
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")
    monkeypatch.setattr(files.tempfile, "mkstemp", read_only)
    err = one_line_error(capsys, ["run", str(folder), "--out", str(tmp_path / "d.npz")])
    assert "cannot write in this folder: Read-only file system" in err


@pytest.mark.skipif(os.geteuid() == 0, reason="run as root: read-only folders are writable to root, "
                                                               "so the refusal cannot be seen")
def test_a_read_only_folder_is_refused(folder, tmp_path, capsys, no_run):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        assert "not writable" in one_line_error(capsys, ["run", str(folder), "--out", str(locked / "d.npz")])
    finally:
        locked.chmod(0o755)


def test_inputs_are_never_overwritten_even_with_force(folder, tmp_path, capsys, no_run):
    events = make_events([0, 1000], [1, 2], [1, 1], [1, 1])
    write_events_npy(tmp_path / "inp.npz", events)
    os.link(tmp_path / "inp.npz", tmp_path / "link.npz")
    os.symlink(tmp_path / "inp.npz", tmp_path / "sym.npz")
    for out in ("inp.npz", "link.npz", "sym.npz"):
        err = one_line_error(capsys, ["run", str(tmp_path / "inp.npz"), "--out", str(tmp_path / out), "--force"])
        assert "would overwrite the input" in err
    assert "would overwrite the input" in one_line_error(
        capsys, ["run", str(folder), "--json", str(folder / "calib.txt"), "--force", "--out", str(tmp_path / "d.npz")])
    assert "would overwrite the input" in one_line_error(
        capsys, ["eval", str(folder), str(tmp_path / "inp.npz"), "--json", str(folder / "events.txt"), "--force"])


def test_existing_outputs_need_force(folder, tmp_path, capsys):
    out = tmp_path / "d.npz"
    out.write_bytes(b"old")
    assert "exists; pass --force" in one_line_error(capsys, ["run", str(folder), "--out", str(out), "--quiet"])
    assert out.read_bytes() == b"old"
    assert main(["run", str(folder), "--out", str(out), "--quiet", "--force"]) == 0
    assert read_depth(out)[0].dtype == DEPTH_DTYPE
    capsys.readouterr()
    # a recording folder tofnet simulate did not write (no manifest): refused even with --force
    before = sorted(p.name for p in folder.iterdir())
    for force in ([], ["--force"]):
        assert "which tofnet did not write" in one_line_error(capsys, ["simulate", "slider", str(folder), "--quiet",
                                                                        *force])
    assert sorted(p.name for p in folder.iterdir()) == before
    simulated = tmp_path / "sim"
    assert main(["simulate", "slider", str(simulated), "--duration", "0.02", "--quiet"]) == 0
    assert "exists; pass --force" in one_line_error(capsys, ["simulate", "slider", str(simulated), "--quiet"])


def test_a_manifest_python_cannot_read_marks_no_folder_as_tofnets(tmp_path):
    from tofnet.io.guard import MANIFEST, read_manifest
    for text in ("[" * 100_000, '{"files": [' + "1" * 5000 + "]}"):  # were RecursionError, ValueError
        (tmp_path / MANIFEST).write_text(text)
        assert read_manifest(tmp_path) is None


def test_missing_output_folders_are_created(folder, tmp_path, capsys):
    out, summary = tmp_path / "new" / "d.csv", tmp_path / "other" / "deep" / "run.json"
    assert main(["run", str(folder), "--out", str(out), "--json", str(summary), "--quiet"]) == 0
    assert out.is_file() and summary.is_file()


# ---------------------------------------------------------------- atomic writes

def _leftovers(folder) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.endswith(".part")]


@pytest.mark.parametrize("name", ["d.npz", "d.csv"])
def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch, name):
    path = tmp_path / name
    path.write_bytes(b"previous contents")

    def full_disk(fd):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(files.os, "fsync", full_disk)
    with pytest.raises(DataError, match="cannot write: No space left on device"):
        write_depth(path, _depth(), t0_us=0, timestep_us=1000, latency_steps=2)
    assert path.read_bytes() == b"previous contents" and _leftovers(tmp_path) == []


def test_an_interrupted_write_leaves_nothing_under_the_final_name(tmp_path, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(np.lib.format, "write_array", interrupted)  # the npz writer's per-array step
    with pytest.raises(KeyboardInterrupt):
        write_depth(tmp_path / "d.npz", _depth(), t0_us=0, timestep_us=1000, latency_steps=2)
    assert list(tmp_path.iterdir()) == []


def test_written_files_get_normal_permissions(tmp_path):
    write_depth(tmp_path / "d.npz", _depth(), t0_us=0, timestep_us=1000, latency_steps=2)
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "d.npz").stat().st_mode & 0o777 == 0o666 & ~mask


# ---------------------------------------------------------------- truncated files are not read as complete

def test_a_truncated_csv_is_never_read_as_complete(tmp_path):
    depth = _depth(200)
    write_depth(tmp_path / "d.csv", depth, t0_us=0, timestep_us=1000, latency_steps=2)
    raw = (tmp_path / "d.csv").read_bytes()
    assert np.array_equal(read_depth(tmp_path / "d.csv")[0], depth)
    for cut in range(1, len(raw), 37):
        (tmp_path / "cut.csv").write_bytes(raw[:cut])
        with pytest.raises(DataError):
            read_depth(tmp_path / "cut.csv")
    lines = raw.decode().splitlines(keepends=True)
    (tmp_path / "gap.csv").write_text("".join(lines[:50] + lines[51:]))
    with pytest.raises(DataError, match="the end line says 200 rows but the file holds 199"):
        read_depth(tmp_path / "gap.csv")


def test_a_truncated_npz_is_never_read_as_complete(tmp_path):
    write_depth(tmp_path / "d.npz", _depth(500), t0_us=0, timestep_us=1000, latency_steps=2)
    raw = (tmp_path / "d.npz").read_bytes()
    for cut in range(1, len(raw), max(1, len(raw) // 60)):
        (tmp_path / "cut.npz").write_bytes(raw[:cut])
        with pytest.raises(DataError):
            read_depth(tmp_path / "cut.npz")


@pytest.mark.parametrize("key, value, message", [
    ("t_us", np.array([0, 2**62, 0]), "array 't', row 1: expected whole µs"),
    ("x", np.array([0.5, 1, 2]), "dtype float64"),
    ("z", np.array([1.0, np.nan, 1.0]), "array 'z', row 1: expected a finite depth"),
    ("step", np.array([0, -1, 2]), "array 'step', row 1"),
])
def test_depth_values_are_checked_on_reading(tmp_path, key, value, message):
    arrays = {"t": np.zeros(3), "t_us": np.zeros(3, np.int64), "x": np.zeros(3, np.uint16),
              "y": np.zeros(3, np.uint16), "z": np.ones(3), "step": np.zeros(3, np.int64), key: value}
    np.savez(tmp_path / "d.npz", **arrays)
    with pytest.raises(DataError, match=message):
        read_depth(tmp_path / "d.npz")


def test_simulate_never_writes_its_summary_over_its_recording_nor_keeps_an_older_ones_files(tmp_path, capsys):
    out = tmp_path / "o"
    err = one_line_error(capsys, ["simulate", "slider", str(out), "--duration", "0.02", "--quiet",
                                  "--json", str(out / "events.txt")])
    assert "inside OUT_DIR" in err and not out.exists()
    cases = [("r.npz", "r.npz"), ("r.npz", "r_depth.npy")]
    if importlib.util.find_spec("faery") is not None:  # writing .aedat4 needs the formats extra
        cases.append(("r.aedat4", "calib.txt"))
    for name, clash in cases:
        err = one_line_error(capsys, ["simulate", "slider", str(tmp_path / name), "--duration", "0.02", "--quiet",
                                      "--json", str(tmp_path / clash)])
        assert "the simulated recording writes" in err and not (tmp_path / name).exists()
    # a rotating scene writes imu.txt; the slider, simulated over it with --force, must not keep it
    assert main(["simulate", "pan", str(out), "--duration", "0.02", "--quiet"]) == 0 and (out / "imu.txt").is_file()
    assert main(["simulate", "slider", str(out), "--duration", "0.02", "--quiet", "--force"]) == 0
    from tofnet.io import read_recording
    assert not (out / "imu.txt").exists() and read_recording(out).imu is None


def test_run_refuses_a_summary_named_as_one_of_its_other_outputs(folder, tmp_path, capsys):
    out = tmp_path / "m.npz"
    monitor = tmp_path / "m.monitor.time_of_travel.counter.npz"
    err = one_line_error(capsys, ["run", str(folder), "--out", str(out), "--monitor", "time_of_travel.counter@1,1",
                                  "--json", str(monitor), "--quiet"])
    assert "--json name the same file" in err and not out.exists() and not monitor.exists()
