"""Outputs replace only what tofnet wrote, and never a file the command reads (issue 27, item 2).

One test per reproducer: an ECD folder output over a folder of other files, the files a
command reads besides the recording (velocity samples, MVSEC's ``*_gt.hdf5``, DSEC's
``cam_to_cam.yaml``, the ``groundtruth.txt`` export reads) through a name, a hard link or
a symlink, and an export over an earlier one.
"""

import os
from pathlib import Path

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.events import DEPTH_DTYPE
from tofnet.io.depth import write_depth
from tofnet.io.guard import MANIFEST

from test_reliability_outputs import folder, one_line_error  # noqa: F401  (a fixture and a helper)
from optional import optional


def _tree(path) -> dict:
    return {str(p.relative_to(path)): p.read_bytes() if p.is_file() else None for p in sorted(path.rglob("*"))}


# ---------------------------------------------------------------- folders tofnet did not write

def test_convert_never_replaces_a_folder_of_other_files(folder, tmp_path, capsys):
    target = tmp_path / "mine"
    (target / "sub").mkdir(parents=True)
    (target / "notes.txt").write_text("precious")
    (target / "sub" / "data.bin").write_bytes(b"\x00\x01")
    before = _tree(target)
    err = one_line_error(capsys, ["convert", str(folder), str(target), "--force", "--quiet"])
    assert "which tofnet did not write" in err and "'notes.txt'" in err
    assert _tree(target) == before


def test_convert_replaces_its_own_folder_and_an_empty_one(folder, tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["convert", str(folder), str(empty), "--quiet"]) == 0  # nothing to lose: no --force needed
    assert (empty / MANIFEST).is_file() and (empty / "events.txt").is_file()
    assert main(["convert", str(folder), str(empty), "--quiet"]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert main(["convert", str(folder), str(empty), "--quiet", "--force"]) == 0
    (empty / "added.txt").write_text("mine")  # added by the user since: the folder is no longer only tofnet's
    assert "'added.txt'" in one_line_error(capsys, ["convert", str(folder), str(empty), "--quiet", "--force"])
    assert (empty / "added.txt").read_text() == "mine"


def test_maps_over_an_earlier_export_leave_exactly_the_new_set(folder, tmp_path, capsys):
    depth = np.zeros(40, dtype=DEPTH_DTYPE)
    depth["t"] = np.arange(40) * 1000
    depth["x"], depth["z"], depth["step"] = 1, 1.5, np.arange(40)
    write_depth(tmp_path / "d.npz", depth, t0_us=0, timestep_us=1000, latency_steps=0,
                summary={"recording": str(folder)})
    maps = tmp_path / "maps"
    assert main(["export", str(tmp_path / "d.npz"), "--maps", str(maps), "--window", "1ms"]) == 0
    assert len(list(maps.glob("depth_*.npy"))) == 40
    assert main(["export", str(tmp_path / "d.npz"), "--maps", str(maps), "--window", "10ms"]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "d.npz"), "--maps", str(maps), "--window", "10ms", "--force"]) == 0
    rows = (maps / "index.csv").read_text().splitlines()[1:]
    assert len(rows) == 4
    names = sorted(p.name for p in maps.iterdir())
    assert names == sorted([MANIFEST, "index.csv", *(f"{kind}_{k:06d}.{ext}" for k in range(4)
                                                     for kind, ext in (("depth", "npy"), ("age", "npy"),
                                                                       ("depth", "png")))])


def test_maps_never_go_into_a_folder_of_other_files(folder, tmp_path, capsys):
    depth = np.zeros(2, dtype=DEPTH_DTYPE)
    depth["t"], depth["z"] = [0, 1000], 1.5
    write_depth(tmp_path / "d.npz", depth, t0_us=0, timestep_us=1000, latency_steps=0,
                summary={"recording": str(folder)})
    assert "holding the input" in one_line_error(
        capsys, ["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path), "--force"])
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.png").write_bytes(b"png")
    err = one_line_error(capsys, ["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path / "photos"), "--force"])
    assert "'a.png', which tofnet did not write" in err
    assert (tmp_path / "photos" / "a.png").read_bytes() == b"png" and (folder / "events.txt").is_file()
    maps = tmp_path / "maps"
    for ply in (maps / "index.csv", maps):  # the folder is replaced as a whole: nothing else goes in it
        err = one_line_error(capsys, ["export", str(tmp_path / "d.npz"), "--maps", str(maps), "--ply", str(ply)])
        assert "inside the --maps folder" in err and not maps.exists()


# ---------------------------------------------------------------- every file a command reads

@pytest.mark.parametrize("how", ["name", "hardlink", "symlink"])
def test_export_never_overwrites_the_groundtruth_it_reads(folder, tmp_path, capsys, how):
    depth = np.zeros(2, dtype=DEPTH_DTYPE)
    depth["t"], depth["z"] = [0, 1000], 1.5
    write_depth(tmp_path / "d.npz", depth, t0_us=0, timestep_us=1000, latency_steps=0,
                summary={"recording": str(folder)})  # the recording comes from the depth file, not an option
    gt = folder / "groundtruth.txt"
    before = gt.read_bytes()
    target = {"name": gt, "hardlink": tmp_path / "gt_link.txt", "symlink": tmp_path / "gt_sym.txt"}[how]
    if how == "hardlink":
        os.link(gt, target)
    elif how == "symlink":
        target.symlink_to(gt)
    err = one_line_error(capsys, ["export", str(tmp_path / "d.npz"), "--ply", str(target), "--force"])
    assert "would overwrite the input" in err
    assert gt.read_bytes() == before


def _samples_spec(tmp_path):
    (tmp_path / "vel.txt").write_text("0 0.5 0 0\n1 0.5 0 0\n")
    spec = tmp_path / "spec.yaml"
    spec.write_text("processes:\n"
                    "  input: {type: InputProcess, sensor_size: [240, 180], timestep: 1ms, refractory: 60ms}\n"
                    "  time_of_travel: {type: TimeOfTravelProcess, distance: 1, counter_bits: 8}\n"
                    "  depth: {type: DepthProcess, min_depth: 0.05, max_depth: 20}\n"
                    f"  velocity: {{type: VelocityProcess, source: samples, samples: {tmp_path / 'vel.txt'},"
                    " intrinsics: [200, 200, 119.5, 89.5]}\n"
                    "connections:\n  - input.events -> time_of_travel.events\n"
                    "  - time_of_travel.counts -> depth.counts\n  - velocity.a_t -> depth.a_t\n")
    return spec


def test_run_never_overwrites_the_velocity_samples_its_spec_reads(folder, tmp_path, capsys):
    spec = _samples_spec(tmp_path)
    before = (tmp_path / "vel.txt").read_bytes()
    err = one_line_error(capsys, ["run", str(folder), "--spec", str(spec), "--out", str(tmp_path / "d.npz"),
                                  "--json", str(tmp_path / "vel.txt"), "--force", "--quiet"])
    assert "would overwrite the input" in err and "vel.txt" in err
    assert (tmp_path / "vel.txt").read_bytes() == before
    assert not (tmp_path / "d.npz").exists()  # refused before the run, not after it


def test_convert_never_overwrites_mvsec_ground_truth(tmp_path, capsys):
    h5py = optional("h5py")
    n = 50
    rows = np.column_stack([np.arange(n) % 8, np.arange(n) % 6, np.arange(n) * 1e-3, np.ones(n)])
    with h5py.File(tmp_path / "indoor_flying1_data.hdf5", "w") as f:
        f.create_dataset("davis/left/events", data=rows)
        f.create_dataset("davis/left/image_raw", data=np.zeros((1, 6, 8), np.uint8))
    with h5py.File(tmp_path / "indoor_flying1_gt.hdf5", "w") as f:
        f.create_dataset("davis/left/pose", data=np.tile(np.eye(4), (2, 1, 1)))
        f.create_dataset("davis/left/pose_ts", data=[0.0, 1.0])
        f.create_dataset("davis/left/depth_image_raw", data=np.full((2, 6, 8), 2.0, np.float32))
        f.create_dataset("davis/left/depth_image_raw_ts", data=[0.0, 0.5])
    gt = tmp_path / "indoor_flying1_gt.hdf5"
    before = gt.read_bytes()
    err = one_line_error(capsys, ["convert", str(tmp_path / "indoor_flying1_data.hdf5"), str(gt), "--force",
                                  "--quiet"])
    assert "would overwrite the input" in err
    assert gt.read_bytes() == before


def test_info_never_overwrites_dsec_calibration(tmp_path, capsys):
    h5py = optional("h5py")
    events = tmp_path / "seq" / "events" / "left"
    events.mkdir(parents=True)
    with h5py.File(events / "events.h5", "w") as f:
        for name, data in (("t", np.arange(20, dtype="<u4") * 100), ("x", np.arange(20) % 8),
                           ("y", np.arange(20) % 6), ("p", np.ones(20, "u1"))):
            f.create_dataset(f"events/{name}", data=data)
        f.create_dataset("t_offset", data=np.int64(0))
        f.create_dataset("ms_to_idx", data=np.array([0, 10, 20]))
    (tmp_path / "seq" / "calibration").mkdir()
    yaml = tmp_path / "seq" / "calibration" / "cam_to_cam.yaml"
    yaml.write_text("intrinsics:\n  cam0:\n    camera_matrix: [555.6, 555.1, 342.3, 218.0]\n"
                    "    distortion_coeffs: [0, 0, 0, 0]\n    distortion_model: radtan\n    resolution: [640, 480]\n")
    before = yaml.read_bytes()
    err = one_line_error(capsys, ["info", str(events / "events.h5"), "--json", str(yaml), "--force", "--quiet"])
    assert "would overwrite the input" in err
    assert yaml.read_bytes() == before


def test_a_writer_refuses_a_file_read_in_the_same_scope(tmp_path):
    """The last line of defence: the atomic writers themselves refuse a file the command read."""
    from tofnet.errors import DataError
    from tofnet.io.files import read_text, write_text_atomic
    from tofnet.io.guard import reading

    path = tmp_path / "side.txt"
    path.write_text("kept")
    with reading():
        read_text(path)
        with pytest.raises(DataError, match="would overwrite the input"):
            write_text_atomic(path, "lost")
    assert path.read_text() == "kept"
    write_text_atomic(path, "replaced")  # outside the command's scope it is an ordinary file
    assert path.read_text() == "replaced"


def test_a_folder_that_cannot_be_listed_is_never_tofnets(tmp_path, monkeypatch):
    from tofnet.io import guard

    (tmp_path / "out").mkdir()
    (tmp_path / "out" / MANIFEST).write_text('{"written_by": "tofnet", "files": []}')
    assert guard.foreign_entries(tmp_path / "out") == []

    def unreadable(path):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(guard.os, "scandir", unreadable)
    assert guard.foreign_entries(tmp_path / "out") == ["(a folder that cannot be listed: Permission denied)"]


def test_only_files_the_manifest_lists_are_tofnets_at_any_depth(tmp_path):
    """A listed ``figures/cloud.png`` once made all of ``figures/`` tofnet's, and any ``.X.part`` its temporary."""
    from tofnet.io import guard
    from tofnet.io.files import write_manifest

    out = tmp_path / "out"
    for name in ("depth.npz", "figures/cloud.png", "recording/events.txt"):
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("tofnet's")
    write_manifest(out, "tofnet demo")
    (out / "empty").mkdir()  # nothing in it to lose
    (out / ".depth.npz.ab_c1234.part").write_text("a killed write")  # tofnet's temporaries for listed files
    (out / "figures" / ".cloud.png.zz999999.old.part").mkdir()
    assert guard.foreign_entries(out) == []
    (out / "figures" / "my_notes.txt").write_text("precious")
    (out / "recording" / "mine").mkdir()
    (out / "recording" / "mine" / "data.txt").write_text("secret")
    (out / ".thesis.part").write_text("draft")  # a user's, though named like a temporary
    (out / ".notes.txt.abcdefgh.part").write_text("no notes.txt is listed")
    (out / "figures" / "link.png").symlink_to(out / "depth.npz")  # tofnet writes no links
    assert guard.foreign_entries(out) == [".notes.txt.abcdefgh.part", ".thesis.part", "figures/link.png",
                                          "figures/my_notes.txt", "recording/mine/data.txt"]
    # a listed folder (a batch's tasks/, filled as its tasks run) covers what is under it
    write_manifest(out, "tofnet batch", ["depth.npz", "figures", "recording"])
    assert guard.foreign_entries(out) == [".notes.txt.abcdefgh.part", ".thesis.part"]


def test_the_outputs_fuzz_target_sees_what_the_guard_prevents(tmp_path, monkeypatch):
    """With the guard switched off, the fuzzer's ``outputs`` target reports the damage it finds."""
    from tofnet import fuzzing
    from tofnet.io import files

    kinds = {}
    for case in fuzzing.seeds("outputs"):
        kinds[" ".join(case)] = fuzzing.outcome(fuzzing.TARGETS["outputs"], case, tmp_path)[0]
    assert set(kinds.values()) <= {"error", "accepted"}, kinds
    monkeypatch.setattr(files, "input_among", lambda *a, **k: None)
    monkeypatch.setattr(files, "inputs_under", lambda *a, **k: None)
    monkeypatch.setattr(files, "foreign_entries", lambda *a, **k: [])
    off = {" ".join(case): fuzzing.outcome(fuzzing.TARGETS["outputs"], case, tmp_path)[0]
           for case in fuzzing.seeds("outputs")}
    assert off["convert rec mine --force --quiet"] == "invalid"
    assert off["run rec --spec spec.yaml --out out.npz --json vel.txt --force --quiet"] == "invalid"
    assert off["export d.npz --ply rec/groundtruth.txt --force"] == "invalid"


def test_the_outputs_fuzz_target_writes_nothing_outside_its_fixture(tmp_path, monkeypatch):
    """A word the mutation left relative (``-1`` taken as the output) once landed in the caller's folder."""
    from tofnet.fuzzing_outputs import run_case

    caller = tmp_path / "caller"
    caller.mkdir()
    monkeypatch.chdir(caller)
    run_case(["convert", "rec", "-1", "--force", "--quiet"], tmp_path / "scratch")
    assert list(caller.iterdir()) == []
    assert (tmp_path / "scratch" / "outputs-case" / "-1" / "events.txt").is_file()
    assert Path.cwd() == caller


def test_an_output_name_too_long_is_one_line(folder, tmp_path, capsys):
    """Found by the fuzzer's outputs target: os.stat's ENAMETOOLONG escaped as a traceback."""
    long = tmp_path / ("9" * 300 + ".npz")
    err = one_line_error(capsys, ["run", str(folder), "--velocity", "0.5,0,0", "--out", str(long), "--quiet"])
    assert err.endswith("--out: File name too long")
    assert one_line_error(capsys, ["convert", str(folder), str(long), "--quiet"]).endswith("File name too long")
    for argv in (["run", str(long), "--velocity", "0.5,0,0", "--out", str(tmp_path / "d.npz"), "--quiet"],
                 ["info", str(long)], ["convert", str(long), str(tmp_path / "c.npz")]):
        assert "no such file or folder" in one_line_error(capsys, argv)  # an input name too long: one line


def test_export_never_quotes_a_file_that_a_depth_file_names_as_its_recording(tmp_path, capsys):
    """A depth file from someone else chooses the recording export reads when --recording is not given:
    what cannot be read is named, never quoted (a secrets file read as events quoted its first field)."""
    secret = tmp_path / "notes.txt"
    secret.write_text("API_KEY=sk-live-0123456789abcdefghij 1 2 3\n")
    write_depth(tmp_path / "d.npz", np.zeros(0, dtype=DEPTH_DTYPE), t0_us=0, timestep_us=1000, latency_steps=2,
                summary={"recording": str(secret)})
    err = one_line_error(capsys, ["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path / "maps")])
    assert "that " in err and "pass --recording PATH" in err and "API_KEY" not in err
    err = one_line_error(capsys, ["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path / "maps"),
                                  "--recording", str(secret)])  # named by the user: the reader's own message
    assert "notes.txt:1" in err
