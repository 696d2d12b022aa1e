"""`tofnet convert` to Prophesee RAW (EVT3), DAT and Event Stream: exact times, side files, refusals."""

import contextlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.events import make_events
from tofnet.io import read_recording
from tofnet.io.arrays import write_events_npy, write_npz_recording
from tofnet.io.convert import convert
from tofnet.io.groundtruth import Trajectory
from tofnet.io.source import open_recording
from optional import optional

faery = optional("faery")

from formats_helpers import T0_US, FullDiskEncoder, faery_events, pattern_recording  # noqa: E402

NEW = [("evt3", "rec.raw"), ("dat", "rec.dat"), ("es", "rec.es")]
REAL = Path(__file__).resolve().parents[1].parent / "shared" / "real"  # ../shared/real beside the checkout
#: The camera clock of the real EVT3 sample starts about here (µs); Event Stream holds such times.
CAMERA_T0_US = 11_194_368


def _depth(recording):
    from tofnet.api import run

    return run(recording, backend="fixed")[0].depth


@pytest.fixture(scope="module")
def camera_clock(tmp_path_factory):
    """The pattern recording on a camera's clock (from 11.2 s) rather than Unix-epoch µs, as a ``.npz``."""
    recording = pattern_recording()
    shift = T0_US - CAMERA_T0_US
    events = recording.events.copy()
    events["t"] -= shift
    poses = recording.trajectory
    recording = replace(recording, events=events, imu=None,
                        trajectory=Trajectory(poses.times - shift * 1e-6, poses.positions, poses.quaternions))
    path = tmp_path_factory.mktemp("camera") / "rec.npz"
    write_npz_recording(path, recording)
    read = read_recording(path)
    depth = _depth(read)
    assert len(depth) > 100  # the comparison below means something
    return read, path, depth


@pytest.mark.parametrize("kind, name", NEW)
def test_reads_back_exactly_with_tofnet_and_faery_and_runs_to_the_same_depth(tmp_path, camera_clock, kind, name):
    original, path, depth = camera_clock
    with open_recording(path) as source:
        messages = convert(source, tmp_path / name)
    assert messages[0] == f"wrote {len(original.events):,} events to {tmp_path / name} ({kind})"
    assert f"calib -> {tmp_path / 'calib.txt'} (read back as a side file)" in messages
    read = read_recording(tmp_path / name)
    assert np.array_equal(read.events, original.events)  # t, x, y, p
    assert read.sensor_size == original.sensor_size and read.intrinsics == original.intrinsics
    assert np.array_equal(read.trajectory.times, original.trajectory.times)
    assert np.array_equal(read.trajectory.positions, original.trajectory.positions)
    assert any("calib.txt next to the file" in note for note in read.notes)
    decoded = np.concatenate(list(faery.events_stream_from_file(tmp_path / name)))  # faery's own decoder
    assert np.array_equal(decoded, faery_events(original.events))
    assert np.array_equal(_depth(read), depth)


@pytest.mark.parametrize("kind, name", NEW[:2])
def test_unix_epoch_times_are_kept_by_raw_and_dat(tmp_path, kind, name):
    # EVT3 and DAT keep the first time in a '% t0' header line: both decoders add it back.
    recording = pattern_recording()
    write_npz_recording(tmp_path / "rec.npz", recording)
    with open_recording(tmp_path / "rec.npz") as source:
        messages = convert(source, tmp_path / "out" / name)
    assert "not written: IMU (41 samples; " + kind + " has no place for it)" in messages
    assert np.array_equal(read_recording(tmp_path / "out" / name).events, recording.events)
    decoded = np.concatenate(list(faery.events_stream_from_file(tmp_path / "out" / name)))
    assert np.array_equal(decoded, faery_events(recording.events))
    assert (tmp_path / "out" / name).stat().st_size < 16 * len(recording.events)  # no clock padding


def _npy(folder: Path, t, x=None) -> Path:
    t = np.asarray(t, dtype=np.int64)
    x = np.arange(len(t)) % 64 if x is None else np.asarray(x)
    write_events_npy(folder / "in.npy", make_events(t, x, np.arange(len(t)) % 48, np.arange(len(t)) % 2))
    return folder / "in.npy"


def _refused(capsys, argv, *expected: str, sensor: str = "64x48") -> None:
    assert main(["convert", *argv, "--quiet", "--sensor-size", sensor]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert all(part in err for part in expected), err


@pytest.mark.parametrize("name, times, expected", [
    ("rec.raw", [-5, 10, 20], "EVT3 stores times >= 0 µs, got -5"),
    ("rec.dat", [-5, 10, 20], "DAT stores times >= 0 µs, got -5"),
    ("rec.es", [-5, 10, 20], "Event Stream stores times >= 0 µs, got -5"),
    ("rec.es", [10, 2**32], "times must be below 4294967296 µs (71.6 min), got 4294967296 µs"),
    ("rec.dat", [10, 2**31 + 10], "less than 2147483648 µs (35.8 min) apart, got 2147483648 µs before 2147483658"),
])
def test_a_time_the_format_cannot_hold_is_one_line_and_nothing_is_written(tmp_path, capsys, name, times, expected):
    source = _npy(tmp_path, times)
    _refused(capsys, [str(source), str(tmp_path / name)], str(tmp_path / name), expected)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.npy"]


def test_dat_wraps_its_32_bit_clock_below_the_gap_limit(tmp_path):
    t = [10 + k * (2**31 - 1) for k in range(6)]  # the largest gap allowed; the clock wraps twice
    source = _npy(tmp_path, t)
    assert main(["convert", str(source), str(tmp_path / "rec.dat"), "--quiet", "--sensor-size", "64x48"]) == 0
    assert read_recording(tmp_path / "rec.dat").events["t"].tolist() == t
    assert np.concatenate(list(faery.events_stream_from_file(tmp_path / "rec.dat")))["t"].tolist() == t


def test_evt3_silences_longer_than_its_24_bit_clock_read_back(tmp_path):
    # The encoder writes the time-high wrap-arounds of a silence; tofnet's decoder counts them
    # (faery 0.7's decoder does not: docs/formats.md).
    t = [10, 20, 20 + 2**24 + 7, 2**30]
    source = _npy(tmp_path, t)
    assert main(["convert", str(source), str(tmp_path / "rec.raw"), "--quiet", "--sensor-size", "64x48"]) == 0
    assert read_recording(tmp_path / "rec.raw").events["t"].tolist() == t


def test_existing_output_large_sensor_and_events_outside_it_are_refused_in_one_line(tmp_path, capsys):
    source = _npy(tmp_path, [10, 20, 30], x=[1, 2, 63])
    (tmp_path / "rec.raw").write_text("precious")
    _refused(capsys, [str(source), str(tmp_path / "rec.raw")], "exists; pass --force to overwrite it")
    assert (tmp_path / "rec.raw").read_text() == "precious"
    assert main(["convert", str(source), str(tmp_path / "big.raw"), "--quiet", "--sensor-size", "4096x48"]) == 2
    assert "EVT3 holds sensors up to 2048 pixels a side; the recording's is 4096x48" in capsys.readouterr().err
    _refused(capsys, [str(source), str(tmp_path / "rec.es")], "event at x=63, y=2 is outside the 32x48 sensor",
             sensor="32x48")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.npy", "rec.raw"]


@contextlib.contextmanager
def _file_size_limit(limit: int):
    """Writes beyond ``limit`` bytes fail (EFBIG) instead of filling the disk, should a guard be missing."""
    resource = pytest.importorskip("resource")
    import signal

    old_limit, old_handler = resource.getrlimit(resource.RLIMIT_FSIZE), signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, old_limit[1]))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, old_limit)
        signal.signal(signal.SIGXFSZ, old_handler)


@pytest.mark.parametrize("kind", ["evt3", "dat", "es"])
def test_events_out_of_time_order_never_reach_faery(tmp_path, kind):
    # faery 0.7's EVT3 encoder, given a time before the file's first, writes time words until the disk is full.
    from tofnet.io.prophesee_write import write_prophesee

    events = make_events(np.arange(10, dtype=np.int64) * 100, np.arange(10), np.arange(10), np.arange(10) % 2)
    meta = type("Meta", (), {"sensor_size": (64, 48)})()
    with _file_size_limit(10**6), pytest.raises(DataError, match="events must be sorted by time; 0 µs comes after "
                                                                 "900 µs"):
        write_prophesee(tmp_path / "out", [events[5:], events[:5]], meta, kind)
    assert (tmp_path / "out").stat().st_size < 1000


def test_encoder_errors_are_one_line(tmp_path, monkeypatch, capsys):
    from faery.extension import evt

    monkeypatch.setattr(evt, "Encoder", FullDiskEncoder)
    source = _npy(tmp_path, [10, 20])
    _refused(capsys, [str(source), str(tmp_path / "rec.raw")], f"{tmp_path / 'rec.raw'}: cannot write: "
                                                                "No space left on device")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.npy"]


@pytest.mark.skipif(not (REAL / "evt3.raw").is_file(), reason="needs the real EVT3 recording, not distributed "
                                                                "with tofnet (shared/real/ beside the checkout)")
def test_real_evt3_through_dat_and_back_keeps_every_event(tmp_path):
    original = read_recording(REAL / "evt3.raw")
    assert len(original.events) == 1_218_618 and original.sensor_size == (1280, 720)
    assert main(["convert", str(REAL / "evt3.raw"), str(tmp_path / "a.dat"), "--quiet"]) == 0
    assert main(["convert", str(tmp_path / "a.dat"), str(tmp_path / "b.raw"), "--quiet"]) == 0
    for name in ("a.dat", "b.raw"):
        assert np.array_equal(read_recording(tmp_path / name).events, original.events)
    assert read_recording(tmp_path / "b.raw").sensor_size == (1280, 720)


def test_a_folder_where_a_side_file_goes_is_refused_before_anything_is_written(tmp_path, capsys):
    pytest.importorskip("faery")
    from tofnet.cli import main
    from tofnet.io import write_ecd
    from tofnet.testing import TEST_INTRINSICS

    from formats_helpers import pattern_recording

    recording = pattern_recording()
    write_ecd(tmp_path / "rec", recording.events, intrinsics=TEST_INTRINSICS, sensor_size=recording.sensor_size)
    (tmp_path / "out" / "calib.txt").mkdir(parents=True)
    assert main(["convert", str(tmp_path / "rec"), str(tmp_path / "out" / "x.raw"), "--force", "--quiet"]) == 2
    assert "calib.txt: side file for the camera or poses: exists and is a folder" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["calib.txt"]


def test_a_side_file_another_recording_reads_is_named_in_the_refusal(camera_clock, tmp_path, capsys):
    source = camera_clock[1]
    assert main(["convert", str(source), str(tmp_path / "a.raw"), "--quiet",
                 "--intrinsics", "200,200,120,90"]) == 0
    assert (tmp_path / "calib.txt").exists()
    capsys.readouterr()
    assert main(["convert", str(source), str(tmp_path / "c.dat"), "--quiet", "--intrinsics", "300,300,120,90"]) == 2
    assert ("calib.txt: exists, and c.dat beside it would be read with it as its camera or poses; a.raw here reads it "
            "too, and would with --force read the new one") in capsys.readouterr().err
    assert read_recording(tmp_path / "a.raw").intrinsics.fx == 200
