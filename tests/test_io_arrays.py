"""Numpy inputs people have: column orders, polarity names, N-ImageNet's key, extra text columns."""

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.events import make_events
from tofnet.io import read_recording
from tofnet.io.events import read_events_npy, read_events_txt
from optional import optional

EVENTS = make_events([1000, 2000, 2000, 5000], [3, 4, 5, 6], [7, 8, 9, 10], [1, 0, 1, 1])


def test_mvsec_style_array_with_column_order(tmp_path):
    # x, y, t in seconds, p in -1/1: read in the default order, the error says how to fix it.
    rows = np.column_stack([EVENTS["x"], EVENTS["y"], EVENTS["t"] * 1e-6, np.where(EVENTS["p"] == 1, 1, -1)])
    np.save(tmp_path / "mvsec.npy", rows)
    with pytest.raises(DataError, match="pass --columns, e.g. x,y,t,p"):
        read_events_npy(tmp_path / "mvsec.npy")
    assert np.array_equal(read_events_npy(tmp_path / "mvsec.npy", columns="x,y,t,p"), EVENTS)
    assert np.array_equal(read_recording(tmp_path / "mvsec.npy", columns=("x", "y", "t", "p")).events, EVENTS)
    np.savez(tmp_path / "rows.npz", events=rows)
    assert np.array_equal(read_events_npy(tmp_path / "rows.npz", columns="x, y, t, p"), EVENTS)
    with pytest.raises(DataError, match="columns must name t, x, y and p once each"):
        read_events_npy(tmp_path / "mvsec.npy", columns="x,y,t,t")


@pytest.mark.parametrize("polarity", ["on", "polarity"])
def test_polarity_field_names(tmp_path, polarity):
    dtype = [("t", "<u8"), ("x", "<u2"), ("y", "<u2"), (polarity, "?")]
    array = np.zeros(len(EVENTS), dtype=dtype)
    for name in "txy":
        array[name] = EVENTS[name]
    array[polarity] = EVENTS["p"] == 1
    np.save(tmp_path / "a.npy", array)
    assert np.array_equal(read_events_npy(tmp_path / "a.npy"), EVENTS)
    np.savez(tmp_path / "a.npz", t=EVENTS["t"], x=EVENTS["x"], y=EVENTS["y"], **{polarity: EVENTS["p"]})
    assert np.array_equal(read_events_npy(tmp_path / "a.npz"), EVENTS)


def test_faery_dtype_with_titled_polarity(tmp_path):
    faery = optional("faery")
    array = np.zeros(len(EVENTS), dtype=faery.EVENTS_DTYPE)
    array["t"], array["x"], array["y"], array["on"] = EVENTS["t"], EVENTS["x"], EVENTS["y"], EVENTS["p"] == 1
    np.save(tmp_path / "faery.npy", array)
    assert np.array_equal(read_events_npy(tmp_path / "faery.npy"), EVENTS)


def test_n_imagenet_event_data_key(tmp_path):
    array = np.zeros(len(EVENTS), dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("p", "?")])
    for name in "xyt":
        array[name] = EVENTS[name]
    array["p"] = EVENTS["p"] == 1
    np.savez_compressed(tmp_path / "n_imagenet.npz", event_data=array)
    assert np.array_equal(read_recording(tmp_path / "n_imagenet.npz").events, EVENTS)


def test_missing_polarity_names_the_accepted_names(tmp_path):
    np.save(tmp_path / "bad.npy", np.zeros(3, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("pol", "u1")]))
    with pytest.raises(DataError, match=r"expected t \(or timestamp\), x, y and p \(or on, polarity\); missing p"):
        read_events_npy(tmp_path / "bad.npy")


def test_text_columns_after_the_fourth_are_ignored(tmp_path):
    path = tmp_path / "events.txt"
    path.write_text("0.001 3 7 1 0.25 extra\n0.002 4 8 0\n0.002 5 9 1 x\n0.005 6 10 1 7 8 9\n")
    assert np.array_equal(read_events_txt(path), EVENTS)


def test_npz_written_by_convert_carries_the_camera(tmp_path):
    from formats_helpers import pattern_recording

    from tofnet.io.arrays import write_npz_recording

    recording = pattern_recording(duration_us=50_000)
    write_npz_recording(tmp_path / "rec.npz", recording)
    read = read_recording(tmp_path / "rec.npz")
    assert np.array_equal(read.events, recording.events)
    assert read.intrinsics == recording.intrinsics and read.sensor_size == recording.sensor_size
    assert np.array_equal(read.trajectory.times, recording.trajectory.times)
    assert np.array_equal(read.imu, recording.imu)
