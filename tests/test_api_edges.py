"""Small API edges (issue 25): each a one-line error or the behaviour a user expects."""

import numpy as np
import pytest

from tofnet.backends import get_backend
from tofnet.cli import main
from tofnet.compiler import compile_network
from tofnet.errors import BackendError, DataError
from tofnet.events import make_events
from tofnet.io import read_recording
from tofnet.io.ecd import write_ecd
from tofnet.io.recording import Intrinsics, Recording
from tofnet.networks import DEFAULT_SENSOR_SIZE, depth_network, improved_network
from tofnet.testing import TEST_INTRINSICS, moving_edge


def test_open_stream_takes_a_velocity_tuple_like_a_constant_velocity():
    compiled = compile_network(depth_network((16, 12)))
    events = moving_edge((16, 12), -50.0, "u")
    backend = get_backend("fixed")
    by_tuple = backend.open_stream(compiled, intrinsics=TEST_INTRINSICS, velocity_source=(0.05, 0, 0))
    from tofnet.io.recording import ConstantVelocity
    by_source = backend.open_stream(compiled, intrinsics=TEST_INTRINSICS,
                                    velocity_source=ConstantVelocity((0.05, 0.0, 0.0)))
    a, b = by_tuple.feed_all(events), by_source.feed_all(events)
    a_result, b_result = by_tuple.close(), by_source.close()
    assert a_result.outputs["depth.depth"].tobytes() == b_result.outputs["depth.depth"].tobytes()
    assert all(np.array_equal(a[k], b[k]) for k in a) and len(a_result.outputs["depth.depth"]) > 0


@pytest.mark.parametrize("bad", ["fast", (0.5, 0), (0.5, float("nan"), 0)])
def test_open_stream_refuses_a_velocity_that_is_neither_in_one_line(bad):
    compiled = compile_network(depth_network((16, 12)))
    with pytest.raises(DataError, match=r"^velocity_source: expected a VelocitySource \(with velocity_at\) or "
                                        r"\(tx, ty, tz\) in m/s, got ") as err:
        get_backend("fixed").open_stream(compiled, intrinsics=TEST_INTRINSICS, velocity_source=bad)
    assert "\n" not in str(err.value)


def test_a_process_larger_than_the_recordings_declared_sensor_is_refused():
    recording = Recording(moving_edge((24, 18), -50.0, "u"), intrinsics=TEST_INTRINSICS, sensor_size=(24, 18),
                          source="rec/")
    network = improved_network((34, 26), velocity={"source": "constant", "velocity": [-0.1, 0.0, 0.0]})
    with pytest.raises(BackendError, match=r"^sensor size mismatch: process 'time_surface' is 34x26 px and rec/ "
                                           r"declares 24x18 px; size the network to the recording \(e\.g\. "
                                           r"--sensor-size 24x18\)$"):
        get_backend("fixed").run(compile_network(network), recording)
    # the paper's network too (any process that declares a size), on the model-by-model backend as well
    with pytest.raises(BackendError, match="process 'input' is 34x26 px"):
        get_backend("reference").run(compile_network(depth_network((34, 26))), recording)
    # a smaller network is a crop: the events outside it are dropped and counted
    cropped = depth_network((20, 18), velocity={"source": "constant", "velocity": [-0.1, 0.0, 0.0]})
    result = get_backend("fixed").run(compile_network(cropped), recording)
    assert result.dropped["out_of_bounds"] == int(np.count_nonzero(recording.events["x"] >= 20))


def test_dv_processing_timestamp_field_is_read_as_time(tmp_path):
    from tofnet.io.arrays import read_events_npy

    events = make_events([10, 20, 30], [1, 2, 3], [4, 5, 6], [1, 0, 1])
    dv = np.zeros(3, dtype=[("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"), ("polarity", "i1")])
    for ours, theirs in (("t", "timestamp"), ("x", "x"), ("y", "y"), ("p", "polarity")):
        dv[theirs] = events[ours]
    np.save(tmp_path / "dv.npy", dv)
    assert np.array_equal(read_events_npy(tmp_path / "dv.npy"), events)
    np.savez(tmp_path / "dv.npz", timestamp=dv["timestamp"], x=dv["x"], y=dv["y"], polarity=dv["polarity"])
    assert np.array_equal(read_recording(tmp_path / "dv.npz").events, events)


def test_info_prints_the_real_range_of_pixels_used(tmp_path, capsys):
    events = make_events([0, 10, 20], [5, 9, 7], [2, 3, 11], [1, 1, 0])
    write_ecd(tmp_path / "rec", events, intrinsics=Intrinsics(100, 100, 8, 6), sensor_size=(16, 12))
    assert main(["info", str(tmp_path / "rec")]) == 0
    out = capsys.readouterr().out
    assert "pixels used    x 5..9, y 2..11" in out


def test_an_ecd_folder_without_a_size_builds_the_cli_default_network(tmp_path):
    write_ecd(tmp_path / "rec", moving_edge((16, 12), -50.0, "u"), intrinsics=TEST_INTRINSICS)
    recording = read_recording(tmp_path / "rec")
    assert recording.sensor_size is None  # the folder names none
    network = depth_network(recording.sensor_size)
    assert network.sensor_size == DEFAULT_SENSOR_SIZE == (240, 180)
    from tofnet.api import default_network
    assert default_network(recording).sensor_size == network.sensor_size  # what `tofnet run` builds


@pytest.mark.parametrize("name", ["rec.npz", "rec.h5", "rec.aedat4"])
def test_simulate_writes_the_formats_convert_writes(tmp_path, capsys, name):
    from optional import optional
    optional({"rec.npz": "numpy", "rec.h5": "h5py", "rec.aedat4": "faery"}[name])

    folder = tmp_path / "ecd"
    assert main(["simulate", "slider", str(folder), "--duration", "0.05", "--sensor-size", "48x36", "--quiet"]) == 0
    assert main(["simulate", "slider", str(tmp_path / name), "--duration", "0.05", "--sensor-size", "48x36",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"to {tmp_path / name}" in out
    expected, got = read_recording(folder), read_recording(tmp_path / name)
    assert np.array_equal(got.events, expected.events) and got.sensor_size == (48, 36)
    assert got.intrinsics == expected.intrinsics  # in the file, or calib.txt beside it
    if name == "rec.npz":
        assert np.array_equal(got.gt_depth, expected.gt_depth)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".tofnet-simulate-")]  # no temporary folder left
    assert main(["simulate", "slider", str(tmp_path / name), "--duration", "0.05", "--quiet"]) == 2  # no --force
    assert "exists" in capsys.readouterr().err
