"""`tofnet convert` and `tofnet.io.convert`: every target reads back to the same depth, bit for bit."""

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.io import read_recording
from tofnet.io.arrays import write_npz_recording
from tofnet.io.convert import convert
from tofnet.io.source import open_recording

from formats_helpers import pattern_recording
from optional import optional

TARGETS = [("ecd", "rec", None), ("npz", "rec.npz", None), ("hdf5", "rec.h5", "h5py"),
           ("aedat4", "rec.aedat4", "faery")]


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    folder = tmp_path_factory.mktemp("original")
    write_npz_recording(folder / "rec.npz", pattern_recording())
    return read_recording(folder / "rec.npz"), folder / "rec.npz"


def _depth(recording):
    from tofnet.api import run

    result, _ = run(recording, backend="fixed")
    return result


@pytest.fixture(scope="module")
def original_depth(original):
    result = _depth(original[0])
    assert len(result.depth) > 100  # the comparison below means something
    return result.depth


@pytest.mark.parametrize("kind, name, needs", TARGETS)
def test_each_target_gives_the_same_depth_bit_for_bit(tmp_path, original, original_depth, kind, name, needs):
    if needs:
        optional(needs)
    recording, path = original
    with open_recording(path) as source:
        messages = convert(source, tmp_path / name)
    assert messages[0].startswith(f"wrote {len(recording.events):,} events")
    read = read_recording(tmp_path / name)
    assert np.array_equal(read.events, recording.events)
    assert read.intrinsics == recording.intrinsics and read.sensor_size == recording.sensor_size
    depth = _depth(read).depth
    assert np.array_equal(depth, original_depth)


def test_chain_through_every_format_is_lossless(tmp_path, original, original_depth):
    optional("h5py")
    optional("faery")
    current = original[1]
    for k, name in enumerate(["a.h5", "b.aedat4", "c", "d.npz", "e.h5"]):
        folder = tmp_path / str(k)
        with open_recording(current) as source:
            convert(source, folder / name)
        current = folder / name
    assert np.array_equal(_depth(read_recording(current)).depth, original_depth)


def test_refuses_to_overwrite_and_leaves_no_partial_file(tmp_path, original):
    (tmp_path / "rec.h5").write_text("precious")
    with open_recording(original[1]) as source, pytest.raises(DataError, match="exists; pass --force"):
        convert(source, tmp_path / "rec.h5")
    assert (tmp_path / "rec.h5").read_text() == "precious"
    with pytest.raises(DataError, match="cannot write '.csv'"):
        convert(open_recording(original[1]), tmp_path / "rec.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.h5"]


def test_equidistant_distortion_is_reported_when_the_target_cannot_hold_it(tmp_path, original):
    from dataclasses import replace

    recording = original[0]
    recording_fisheye = replace(recording.intrinsics, distortion=(0.1, 0.01, 0.0, 0.0), distortion_model="equidistant")
    source = open_recording(original[1])
    source.intrinsics = recording_fisheye
    messages = convert(source, tmp_path / "rec")
    assert any("equidistant coefficients (0.1, 0.01, 0.0, 0.0) are NOT written" in m for m in messages)
    assert read_recording(tmp_path / "rec").intrinsics.distortion == ()


def test_cli_convert_and_info(tmp_path, original, capsys):
    optional("h5py")
    assert main(["convert", str(original[1]), str(tmp_path / "rec.h5"), "--quiet"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["convert", str(original[1]), str(tmp_path / "rec.h5"), "--quiet"]) == 2
    assert "exists; pass --force to overwrite it" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "rec.h5"), "--quiet", "--json", str(tmp_path / "info.json")]) == 0
    out = capsys.readouterr().out
    events = original[0].events
    assert f"events         {len(events):,}" in out and "hdf5 (DSEC layout)" in out
    on = np.count_nonzero(events["p"]) / len(events)
    assert f"ON {on:.1%}" in out
    import json
    facts = json.loads((tmp_path / "info.json").read_text())
    assert facts["events"] == len(events) and facts["sensor_size"] == [64, 48]
    assert facts["poses"]["count"] == len(original[0].trajectory.times) and facts["imu_samples"] == 41


@pytest.mark.parametrize("name, module, extra", [("rec.aedat4", "faery", "formats"), ("rec.h5", "h5py", "hdf5"),
                                                ("rec.raw", "faery", "formats"), ("rec.dat", "faery", "formats"),
                                                ("rec.es", "faery", "formats")])
def test_a_writer_without_its_library_is_refused_in_one_line_before_any_work(tmp_path, monkeypatch, capsys,
                                                                              original, name, module, extra):
    import sys
    monkeypatch.setitem(sys.modules, module, None)  # not installed
    for argv in (["convert", str(original[1]), str(tmp_path / name)],
                 ["simulate", "slider", str(tmp_path / name), "--duration", "0.01", "--quiet"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and f'pip install "tofnet[{extra}]"' in err and "Traceback" not in err
        assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing written, not even a partial file


def test_an_npz_that_holds_its_camera_is_not_noted_as_without_one(tmp_path, original):
    from dataclasses import replace

    recording, path = original
    assert recording.intrinsics is not None and not any("intrinsics unknown" in n for n in recording.notes)
    bare = tmp_path / "bare.npz"
    write_npz_recording(bare, replace(recording, intrinsics=None))
    again = read_recording(bare)
    assert again.intrinsics is None and "no calib.txt: intrinsics unknown" in again.notes


def test_convert_says_what_of_an_hdf5_it_does_not_write(tmp_path, original, capsys):
    h5py = pytest.importorskip("h5py")
    events = original[0].events
    path = tmp_path / "dsec.h5"
    with h5py.File(path, "w") as h5:
        for key in ("x", "y", "t", "p"):
            h5[f"events/{key}"] = events[key]
        h5["t_offset"] = np.int64(0)
        h5["images"] = np.zeros((3, 4, 5), np.uint8)  # a stream tofnet does not read
    assert main(["convert", str(path), str(tmp_path / "out.npz"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "not written: images (tofnet reads only the events, camera, poses and IMU of dsec.h5)" in out, out


def test_a_side_file_of_another_recording_beside_the_output_is_refused_before_any_work(tmp_path, original, capsys):
    """A file that keeps its camera beside it (``.dat``: ``calib.txt``) would be read with a stranger's: refused in
    one line, nothing written; ``--force`` replaces it; the input's own side file is its camera and stays."""
    optional("faery")
    out = tmp_path / "other"
    out.mkdir()
    (out / "calib.txt").write_text("100 100 50 50\n")  # another recording's camera
    assert main(["convert", str(original[1]), str(out / "rec.dat")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "calib.txt" in err and "--force" in err and "Traceback" not in err
    assert sorted(p.name for p in out.iterdir()) == ["calib.txt"]
    assert (out / "calib.txt").read_text() == "100 100 50 50\n"
    assert main(["convert", str(original[1]), str(out / "rec.dat"), "--force"]) == 0
    assert read_recording(out / "rec.dat").intrinsics == original[0].intrinsics
    # converting within the input's folder: its calib.txt is its own camera (an input), kept as it is
    mine = tmp_path / "mine"
    assert main(["convert", str(original[1]), str(mine)]) == 0  # an ECD folder with calib.txt
    before = (mine / "calib.txt").read_bytes()
    capsys.readouterr()
    assert main(["convert", str(mine), str(mine / "rec.dat")]) == 0
    assert f"NOT written: {mine / 'calib.txt'} is an input of this conversion" in capsys.readouterr().out
    assert (mine / "calib.txt").read_bytes() == before
    assert read_recording(mine / "rec.dat").intrinsics == original[0].intrinsics


def test_forcing_past_another_recordings_side_file_with_a_camera_less_input_says_it_stays(tmp_path, original,
                                                                                         capsys):
    """``--force`` with an input that has no camera: nothing replaces the stranger's ``calib.txt``, which is not
    removed (tofnet did not write it) but named in a NOTE, since the output will be read with it."""
    from dataclasses import replace

    optional("faery")
    bare = tmp_path / "bare.npz"
    write_npz_recording(bare, replace(original[0], intrinsics=None, trajectory=None))
    out = tmp_path / "other"
    out.mkdir()
    (out / "calib.txt").write_text("100 100 50 50\n")
    assert main(["convert", str(bare), str(out / "rec.dat"), "--force"]) == 0
    printed = capsys.readouterr().out
    assert f"NOTE: {out / 'calib.txt'} is not this input's (it has no camera) and stays" in printed, printed
    assert "groundtruth.txt" not in printed  # none there: nothing to say
    assert (out / "calib.txt").read_text() == "100 100 50 50\n"
