"""A file a dataset ships beside the events (ground truth, calibration, mocap, IMU, the events of a
sequence folder) that exists but is not a regular file -- a FIFO, a folder -- is a one-line error
naming it and what it is, never taken for missing (docs/reliability.md, "Reading files"); one
that is truly absent stays optional where it was. A reader that waits on a FIFO is let go by a
watchdog process (``tests.fifos``): a regression fails instead of hanging."""

from __future__ import annotations

import os
import re
import shutil

import pytest

from tests.optional import optional

h5py = optional("h5py")

from tests.fifos import needs_fifo, watched  # noqa: E402 - a reader waiting on a FIFO fails, not hangs
from tofnet.cli import main  # noqa: E402
from tofnet.errors import DataError  # noqa: E402
from tofnet.io import detect_format, open_recording, read_recording  # noqa: E402
from tofnet.testing_datasets import MAKERS  # noqa: E402

NAMES = {"dsec": "zurich_city_00_a", "mvsec": "indoor_flying1", "tumvie": "mocap-desk2", "m3ed": "car_urban_day_1",
         "evimo2": "scene13_dyn_test_00_000000"}
FIFO = "is a FIFO (named pipe), expected"
FOLDER = "is a folder, expected"


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    root = tmp_path_factory.mktemp("datasets")
    return {kind: make(root / NAMES[kind], duration_s=0.5) for kind, make in MAKERS.items()}


@pytest.fixture
def copy(made, tmp_path):
    return lambda kind: shutil.copytree(made[kind], tmp_path / made[kind].name)


def _replace(path, kind: str) -> None:
    """Put a FIFO or a folder where the file ``path`` was."""
    shutil.rmtree(path) if path.is_dir() else path.unlink()
    os.mkfifo(path) if kind == "fifo" else path.mkdir()


def _refused(call, path, message: str) -> str:
    """The one-line error of ``call()``, which names ``path`` and says ``message``."""
    outcome = watched(call, path if path.exists() and not path.is_dir() else None)
    err = outcome.get("error")
    assert isinstance(err, DataError), outcome
    text = str(err)
    assert "\n" not in text and f"{path.name}: {message}" in text, text
    return text


#: (layout, the file, what the error says it should have been); the events file is read from the folder.
SIDE_FILES = [
    ("mvsec", "indoor_flying1_gt.hdf5", "the MVSEC ground truth (HDF5)"),
    ("mvsec", "indoor_flying_calib/camchain-imucam-indoor_flying.yaml", "the MVSEC calibration file"),
    ("m3ed", "car_urban_day_1_depth_gt.h5", "the M3ED depth ground truth (HDF5)"),
    ("tumvie", "mocap-desk2-vi_gt_data/mocap_data.txt", "the TUM-VIE mocap poses (text)"),
    ("tumvie", "mocap-desk2-vi_gt_data/imu_data.txt", "the TUM-VIE IMU samples (text)"),
    ("tumvie", "camera-calibrationA.json", "the TUM-VIE camera calibration file"),
    ("tumvie", "mocap-imu-calibrationA.json", "the TUM-VIE mocap-IMU calibration file"),  # was a note: "not used"
    ("mvsec", "indoor_flying1_data.hdf5", "a regular file (*_data.hdf5: a sequence's events)"),
    ("m3ed", "car_urban_day_1_data.h5", "a regular file (*_data.h5: a sequence's events)"),
    ("tumvie", "mocap-desk2-events_left.h5", "a regular file (*-events_left.h5: a sequence's events)"),
    ("evimo2", "dataset_depth.npz", "the EVIMO2 depth frames"),
    ("evimo2", "dataset_info.npz", "a file of the EVIMO2 sequence"),
    ("evimo2", "dataset_events_xy.npy", "a file of the EVIMO2 sequence"),
]


@needs_fifo
@pytest.mark.parametrize("kind", ["fifo", "folder"])
@pytest.mark.parametrize("layout, name, what", SIDE_FILES)
def test_a_fifo_or_folder_in_a_sequence_folder_is_named_not_missing(copy, layout, name, what, kind):
    folder = copy(layout)
    _replace(folder / name, kind)
    _refused(lambda: read_recording(folder), folder / name, f"{FIFO if kind == 'fifo' else FOLDER} {what}")


@needs_fifo
@pytest.mark.parametrize("layout, events, name, what", [
    ("mvsec", "indoor_flying1_data.hdf5", "indoor_flying1_gt.hdf5", "the MVSEC ground truth (HDF5)"),
    ("m3ed", "car_urban_day_1_data.h5", "car_urban_day_1_depth_gt.h5", "the M3ED depth ground truth (HDF5)"),
    ("mvsec", "indoor_flying1_data.hdf5", "indoor_flying_calib/camchain-imucam-indoor_flying.yaml",
     "the MVSEC calibration file"),
    ("tumvie", "mocap-desk2-events_left.h5", "mocap-desk2-vi_gt_data/mocap_data.txt", "the TUM-VIE mocap poses (text)"),
])
def test_an_events_file_read_alone_names_a_fifo_companion(copy, layout, events, name, what):
    folder = copy(layout)
    _replace(folder / name, "fifo")
    _refused(lambda: read_recording(folder / events), folder / name, f"{FIFO} {what}")


@needs_fifo
def test_info_on_an_mvsec_folder_with_a_fifo_gt_is_one_line_exit_2(copy, capsys):
    folder = copy("mvsec")
    _replace(folder / "indoor_flying1_gt.hdf5", "fifo")
    outcome = watched(lambda: main(["info", str(folder)]), folder / "indoor_flying1_gt.hdf5")
    assert outcome.get("value") == 2, outcome
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.endswith(f"indoor_flying1_gt.hdf5: {FIFO} the MVSEC ground truth (HDF5)")


@needs_fifo
@pytest.mark.parametrize("layout, name, what", [
    ("dsec", "disparity", "the folder of the disparity ground truth"),
    ("dsec", "disparity/event", "the folder of the disparity maps (*.png)"),
    ("tumvie", "mocap-desk2-vi_gt_data", "the folder of the TUM-VIE ground truth"),
])
def test_a_fifo_where_a_ground_truth_folder_goes_is_named_not_missing(copy, layout, name, what):
    folder = copy(layout)
    _replace(folder / name, "fifo")
    _refused(lambda: read_recording(folder), folder / name, f"{FIFO} {what}")


def test_absent_side_files_stay_optional(copy):
    mvsec, m3ed, tumvie = copy("mvsec"), copy("m3ed"), copy("tumvie")
    (mvsec / "indoor_flying1_gt.hdf5").unlink()
    assert read_recording(mvsec).trajectory is None
    (m3ed / "car_urban_day_1_depth_gt.h5").unlink()
    assert read_recording(m3ed).frame_gt is None
    (tumvie / "mocap-desk2-vi_gt_data" / "imu_data.txt").unlink()
    recording = read_recording(tumvie)
    assert recording.imu is None and recording.trajectory is not None
    shutil.rmtree(tumvie / "mocap-desk2-vi_gt_data")
    assert read_recording(tumvie).trajectory is None
    evimo2 = copy("evimo2")
    (evimo2 / "dataset_depth.npz").unlink()
    assert read_recording(evimo2).frame_gt is None


def test_a_symlink_to_nothing_is_named_not_missing(copy):
    folder = copy("mvsec")
    gt = folder / "indoor_flying1_gt.hdf5"
    gt.unlink()
    gt.symlink_to(folder / "gone.hdf5")
    _refused(lambda: read_recording(folder), gt, "is a symbolic link to nothing, expected the MVSEC ground truth")


@needs_fifo
def test_ground_truth_swapped_for_a_fifo_after_the_source_closed_is_refused(copy):
    """``tofnet eval`` reads depth images after the events' source was closed: h5py opens the file
    again by name, after the same check."""
    folder = copy("mvsec")
    source = open_recording(folder)
    frames = source.frame_gt
    source.close()
    _replace(folder / "indoor_flying1_gt.hdf5", "fifo")
    _refused(lambda: frames._read(0), folder / "indoor_flying1_gt.hdf5", f"{FIFO} the ground truth (HDF5)")


@needs_fifo
@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_a_fifo_or_folder_named_metadata_yaml_is_not_taken_for_another_layout(tmp_path, kind):
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").touch()
    _replace(tmp_path / "bag" / "metadata.yaml", kind)
    _refused(lambda: detect_format(tmp_path / "bag"), tmp_path / "bag" / "metadata.yaml",
             f"{FIFO if kind == 'fifo' else FOLDER} the ROS 2 bag metadata file")


@needs_fifo
@pytest.mark.parametrize("name", ["calib.txt", "groundtruth.txt", "imu.txt", "sensor_size.txt", "events_depth.npy"])
@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_ecd_side_files_that_are_not_regular_files_are_refused(tmp_path, name, kind):
    """Already refused by their readers (``open_regular`` on the descriptor): kept that way."""
    from tofnet.io.ecd import write_ecd
    from tofnet.testing_datasets import plane_events

    write_ecd(tmp_path / "rec", plane_events(2.0, (-0.5, 0.0, 0.0), 0.05), intrinsics=None)
    (tmp_path / "rec" / name).touch()
    _replace(tmp_path / "rec" / name, kind)
    _refused(lambda: read_recording(tmp_path / "rec"), tmp_path / "rec" / name,
             "is a FIFO (named pipe), expected a regular" if kind == "fifo" else "is a folder, expected a regular")


@needs_fifo
def test_present_is_false_only_when_nothing_has_the_name(tmp_path):
    from tofnet.io.files import present

    assert not present(tmp_path / "absent.txt", "x") and not present(tmp_path / "no" / "such.txt", "x")
    assert not present(tmp_path / "bad\x00name", "x")
    (tmp_path / "file.txt").write_text("1\n")
    assert present(tmp_path / "file.txt", "x") and present(tmp_path, "x", folder=True)
    assert not present(tmp_path / "file.txt" / "under", "x")  # under a file: nothing can be there
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(DataError, match=re.escape(f"fifo: {FIFO} the thing")):
        present(tmp_path / "fifo", "the thing")
    with pytest.raises(DataError, match=re.escape(f"fifo: {FIFO} the folder")):
        present(tmp_path / "fifo", "the folder", folder=True)
    with pytest.raises(DataError, match="file.txt: is a file, expected the folder"):
        present(tmp_path / "file.txt", "the folder", folder=True)
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(DataError, match="loop: cannot look up the thing: Too many levels of symbolic links"):
        present(tmp_path / "loop", "the thing")
