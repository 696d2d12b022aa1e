"""The real sensor recordings in ../shared/real/ (see its README): counts, clocks, spans, IMU, runs.

Skipped when the folder is absent (a fresh clone does not have it) or faery is not installed.
"""

from pathlib import Path

import numpy as np
import pytest

from tofnet.io import read_recording
from tofnet.io.recording import ConstantVelocity, Intrinsics
from tofnet.io.source import open_recording
from optional import optional

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "real"  # ../shared/real beside the checkout
pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason="needs the real recordings, not distributed with tofnet "
                                                             "(a shared/real/ folder beside the checkout)")
optional("faery")

#: The README's facts (decoded with faery 0.7.1).
EVT3_DAT_EVENTS = 1_218_618
EVT3_MINUS_DAT_US = 11_194_368


@pytest.fixture(scope="module")
def evt3():
    return read_recording(REAL / "evt3.raw")


@pytest.fixture(scope="module")
def dat():
    return read_recording(REAL / "gen4.dat")


def test_evt3_and_dat_hold_the_same_events_one_clock_offset_apart(evt3, dat):
    assert len(evt3.events) == len(dat.events) == EVT3_DAT_EVENTS
    for name in ("x", "y", "p"):
        assert np.array_equal(evt3.events[name], dat.events[name])
    offset = evt3.events["t"] - dat.events["t"]
    assert np.all(offset == EVT3_MINUS_DAT_US)
    assert evt3.sensor_size == dat.sensor_size == (1280, 720)


def test_evt3_time_high_wraps_are_decoded(evt3):
    # A wrong time-high wrap shows as 4096 µs jumps and a span of about twice 10.77 s.
    assert abs(evt3.duration - 10.77) < 0.01
    gaps = np.diff(evt3.events["t"])
    assert gaps.min() >= 0 and gaps.max() < 4096


def test_evt2_count_and_span():
    recording = read_recording(REAL / "evt2.raw")
    assert len(recording.events) == 521_252
    assert abs(recording.duration - 0.096) < 0.001
    assert recording.sensor_size == (640, 480)  # the header has no geometry: the events' extent


def test_aedat4_events_imu_and_unix_clock():
    source = open_recording(REAL / "davis346.aedat4")
    assert source.sensor_size == (346, 260) and source.n_events == 78_830
    assert {"frame (track 1)", "triggers (track 3)"} <= set(source.streams)
    recording = source.read()
    assert len(recording.events) == 78_830
    t = recording.events["t"]
    assert 1.5e15 < t[0] < 1.7e15 and abs(recording.duration - 2.36) < 0.01  # Unix epoch µs
    imu = recording.imu
    assert imu.shape == (2363, 7)
    assert abs(np.median(np.linalg.norm(imu[:, 1:4], axis=1)) - 9.81) < 0.5  # a static camera feels g (m/s²)
    assert np.std(imu[:, 4:7], axis=0).max() < np.radians(0.2)  # README: gyro std ~0.1 deg/s, here in rad/s


@pytest.mark.parametrize("name, sensor", [("evt2.raw", (640, 480)), ("davis346.aedat4", (346, 260))])
def test_run_counts_every_event(name, sensor):
    from tofnet.api import run

    recording = read_recording(REAL / name)
    recording.intrinsics = Intrinsics(500.0, 500.0, sensor[0] / 2, sensor[1] / 2)
    recording.trajectory = ConstantVelocity((0.3, 0.0, 0.0))
    result, _ = run(recording, backend="fixed")
    assert result.events_in == len(recording.events)
    assert result.accepted + sum(result.dropped.values()) == result.events_in
    assert result.dropped.get("out_of_bounds", 0) == 0


def test_run_on_evt3_and_dat_gives_the_same_depth(evt3, dat):
    from tofnet.api import run

    results = []
    for recording in (evt3, dat):
        recording.intrinsics = Intrinsics(1000.0, 1000.0, 640.0, 360.0)
        recording.trajectory = ConstantVelocity((0.5, 0.0, 0.0))
        result, _ = run(recording, backend="fixed")
        assert result.events_in == EVT3_DAT_EVENTS
        results.append(result.depth)
    for name in ("x", "y", "z", "step"):
        assert np.array_equal(results[0][name], results[1][name])
    assert np.all(results[0]["t"] - results[1]["t"] == EVT3_MINUS_DAT_US)


@pytest.mark.parametrize("name, span", [
    ("evt3.raw", "@11.200224 s .. @21.968221 s (10.768 s)"),
    ("davis346.aedat4", "@1589163147.368868 s .. @1589163149.728813 s (2.35994 s)")])
def test_a_window_before_the_recording_says_its_true_span(name, span):
    from tofnet.errors import DataError
    from tofnet.io.window import parse_window

    for window, asked in ((parse_window(start="@5s", duration="1s"), "@5.000000 s .. @6.000000 s"),
                          (parse_window(start="@0s", duration="11.2s"), "@0.000000 s .. @11.200000 s")):
        with pytest.raises(DataError) as err:
            read_recording(REAL / name, window=window)
        assert str(err.value) == (f"{REAL / name}: no events in the time window {asked}; the recording's events "
                                  f"span {span}")


def test_convert_says_the_aedat4_frames_and_triggers_are_not_written(tmp_path):
    from tofnet.io.convert import convert

    with open_recording(REAL / "davis346.aedat4") as source:
        messages = convert(source, tmp_path / "out.aedat4")
    assert ("not written: frame (track 1), 59 frames 346x260; triggers (track 3), 236 triggers (tofnet reads only "
            "the events, camera, poses and IMU of davis346.aedat4)") in messages
    assert open_recording(tmp_path / "out.aedat4").streams == {"imus (track 1)": "2363 samples (read as the IMU)"}
