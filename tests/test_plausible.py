"""Values a real file can hold but that usually mean another clock, unit or camera: a note each (tofnet.io.plausible);
values no camera has: refused. Each case is a mistake found by feeding perturbed recordings to tofnet."""

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError, TofnetError
from tofnet.io.calibration import parse_intrinsics, read_calibration
from tofnet.io.ecd import write_ecd
from tofnet.io.recording import Intrinsics
from tofnet.io.source import open_recording

from formats_helpers import INTRINSICS, SENSOR, pattern_recording


@pytest.fixture(scope="module")
def recording():
    return pattern_recording(duration_us=200_000)


def _folder(tmp_path, recording, *, times=None, quaternions=None, intrinsics=INTRINSICS, events=None):
    traj = recording.trajectory
    folder = tmp_path / "rec"
    write_ecd(folder, recording.events if events is None else events, intrinsics=intrinsics,
              times=traj.times if times is None else times, positions=traj.positions,
              quaternions=traj.quaternions if quaternions is None else quaternions, sensor_size=SENSOR)
    return folder


def _notes(path, **options):
    return open_recording(path, **options).notes


def test_a_correct_recording_has_none_of_these_notes(tmp_path, recording):
    notes = " | ".join(_notes(_folder(tmp_path, recording)))
    for phrase in ("overlap", "cover", "apart", "events/s", "principal point", "qw"):
        assert phrase not in notes


def test_poses_on_another_clock_are_noted(tmp_path, recording):
    times = recording.trajectory.times + 1e9  # a clock offset
    notes = _notes(_folder(tmp_path, recording, times=times))
    assert any("do not overlap the events" in note and "another clock" in note for note in notes)


def test_poses_covering_part_of_the_events_are_noted(tmp_path, recording):
    traj = recording.trajectory
    first = recording.events["t"][0] * 1e-6
    times = first + (traj.times - traj.times[0]) * 0.25  # the same poses squeezed into the first quarter
    notes = _notes(_folder(tmp_path, recording, times=times))
    assert any("of the events' time span" in note and "extrapolated" in note for note in notes)


def test_pose_times_in_other_units_are_noted(tmp_path, recording):
    traj = recording.trajectory
    times = traj.times[0] + (traj.times - traj.times[0]) * 1e6  # µs written where seconds go
    notes = _notes(_folder(tmp_path, recording, times=times))
    assert any("s apart (median)" in note for note in notes)


def test_event_times_in_microseconds_read_as_seconds_are_noted(tmp_path, recording):
    events = recording.events.copy()
    events["t"] = (events["t"] - events["t"][0]) * 1_000_000  # what events.txt holding µs reads as
    folder = _folder(tmp_path, recording, events=events)
    notes = _notes(folder)
    assert any("events/s): times in other units?" in note for note in notes)


def test_a_run_says_its_doubts_before_it_starts(tmp_path, recording, capsys):
    folder = _folder(tmp_path, recording, times=recording.trajectory.times + 1e9)
    assert main(["run", str(folder), "--out", str(tmp_path / "d.npz"), "--duration", "20ms"]) == 0
    err = capsys.readouterr().err
    assert "tofnet run: note: the poses (" in err and "do not overlap the events" in err
    out = tmp_path / "v.npz"
    assert main(["run", str(folder), "--out", str(out), "--duration", "20ms", "--velocity", "0.5,0,0"]) == 0
    assert "tofnet run: note: the poses" not in capsys.readouterr().err  # --velocity: the poses are not used


def test_a_principal_point_outside_the_sensor_and_w_first_quaternions_are_noted(tmp_path, recording):
    wide = Intrinsics(99.5, 99.4, 200.0, 150.0)  # a 640x480 camera's, on a 64x48 sensor
    w_first = recording.trajectory.quaternions[:, [3, 0, 1, 2]]
    notes = _notes(_folder(tmp_path, recording, intrinsics=wide, quaternions=w_first))
    assert any("principal point (200, 150) px is outside the 64x48 sensor" in note for note in notes)
    assert any("quaternions written w first?" in note for note in notes)


def test_normalised_intrinsics_are_refused_everywhere(tmp_path):
    (tmp_path / "calib.txt").write_text("0.83 1.1 0.55 0.61\n")
    with pytest.raises(DataError, match="calib.txt:1: focal lengths of fx 0.83, fy 1.1 px are below 1 px"):
        read_calibration(tmp_path / "calib.txt")
    with pytest.raises(TofnetError, match="--intrinsics: focal lengths of .* below 1 px: normalised intrinsics"):
        parse_intrinsics("0.83,1.1,0.55,0.61")


def test_a_calibration_of_another_resolution_is_noted_and_the_no_calibration_note_goes(tmp_path, recording):
    folder = _folder(tmp_path, recording)
    (folder / "calib.txt").unlink()
    (tmp_path / "camchain.yaml").write_text(
        "cam0:\n  camera_model: pinhole\n  intrinsics: [226.38, 226.15, 173.65, 133.73]\n"
        "  distortion_model: none\n  distortion_coeffs: [0, 0, 0, 0]\n  resolution: [346, 260]\n")
    notes = _notes(folder, calib=tmp_path / "camchain.yaml")
    assert any("is a 346x260 camera's calibration, the recording's sensor is 64x48" in note for note in notes)
    assert "no calib.txt: intrinsics unknown" not in notes
    assert open_recording(folder, calib=tmp_path / "camchain.yaml").intrinsics.distortion == ()  # model 'none'


def test_float32_times_that_lose_the_microseconds_are_refused(tmp_path):
    n = 2000
    path = tmp_path / "epoch.npz"
    np.savez(path, t=(1.6e9 + np.arange(n) * 1e-4).astype(np.float32), x=np.zeros(n, np.uint16),
             y=np.zeros(n, np.uint16), p=np.ones(n, np.int8))
    with pytest.raises(DataError, match=r"field 't': float32 seconds step by 128 s .* coarser than a 1 ms step"):
        open_recording(path)
    np.savez(path, t=(np.arange(n) * 1e-4).astype(np.float32), x=np.zeros(n, np.uint16), y=np.zeros(n, np.uint16),
             p=np.ones(n, np.int8))
    assert len(open_recording(path).read().events) == n  # 0.2 s: float32 holds µs there


def test_small_text_mistakes_are_read(tmp_path, recording):
    (tmp_path / "calib.txt").write_text("200 201 120 90 -0.3 0.1 0.001 0.002\n")  # k3 left out
    assert read_calibration(tmp_path / "calib.txt").distortion == (-0.3, 0.1, 0.001, 0.002, 0.0)
    folder = _folder(tmp_path, recording)
    gt = folder / "groundtruth.txt"
    gt.write_bytes(b"\xef\xbb\xbf# t px py pz qx qy qz qw\n" + gt.read_bytes())  # a Windows editor's BOM
    assert len(open_recording(folder).trajectory.times) == len(recording.trajectory.times)


def test_an_evt3_header_with_a_malformed_t0_is_refused(tmp_path, capsys):
    path = tmp_path / "rec.raw"
    path.write_bytes(b"% evt 3.0\n% geometry 64x48\n% t0 1.5\n" + np.zeros(4, dtype="<u2").tobytes())
    assert main(["info", str(path)]) == 2
    assert "header line '% t0': expected the time base in whole µs (0 or more), got '1.5'" in capsys.readouterr().err


def test_nanoseconds_of_a_microsecond_clock_are_noted_and_a_millisecond_clock_is_not(tmp_path, recording):
    """Times all alike modulo 1000 with about one event each: noted; said before a run (a doubt) only when they
    are ns since 1970; a busy clock of whole ms (many events per tick) is not noted."""
    from tofnet.io.arrays import write_npz_recording
    from tofnet.io.recording import Recording

    def opened(times, name):
        events = recording.events.copy()
        events["t"] = times
        path = tmp_path / name
        write_npz_recording(path, Recording(events=events, sensor_size=SENSOR, intrinsics=recording.intrinsics))
        source = open_recording(path)
        return " | ".join(source.notes), " | ".join(note for _, note in source.doubts)

    t = recording.events["t"][0] + 30 * np.arange(len(recording.events), dtype=np.int64)  # one event per µs time
    assert "modulo 1000" not in opened(t, "us.npz")[0]  # a µs clock: every residue
    in_ns, doubts = opened(t * 1000 + 417, "ns.npz")  # Unix-epoch ns of a µs clock, with an offset in ns
    assert "event times are all 417 modulo 1000 µs" in in_ns and "nanoseconds of a µs clock, or a clock" in in_ns
    assert "read as µs it lasts 201 s, in ns 0.201 s" in in_ns and "modulo 1000" in doubts
    ticks = t[0] // 1000 + np.arange(len(t), dtype=np.int64) // 2
    quiet_ms, doubts = opened(ticks * 1000, "quiet.npz")  # a quiet sensor's ms clock: 2 events a tick
    assert "modulo 1000" in quiet_ms and "modulo 1000" not in doubts  # noted, not said before a run
    assert "modulo 1000" not in opened(recording.events["t"] // 1000 * 1000, "ms.npz")[0]  # 5 events a tick
    folder = _folder(tmp_path, recording, events=recording.events)
    assert "modulo 1000" not in " | ".join(_notes(folder))
