"""`tofnet run` end to end on ECD folders, its summary, its outputs and its one-line errors."""

import json

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.io import read_depth
from tofnet.io.ecd import write_ecd
from tofnet.io.recording import Intrinsics
from tofnet.kernels.fixed_point import depth_tolerance
from tofnet.testing import moving_edge

SENSOR = (240, 180)
INTRINSICS = Intrinsics(200.0, 200.0, 119.5, 89.5)
DEPTH_M, SPEED_M_S = 2.0, 0.5  # the edge's depth; the camera slides along +x


def straight_edge_recording(folder, *, duration_s=1.0):
    """A vertical edge at DEPTH_M seen by a camera sliding along +x: it moves at -f*v/Z px/s."""
    flow = -INTRINSICS.fx * SPEED_M_S / DEPTH_M  # -50 px/s: 20 steps of 1 ms per pixel
    events = moving_edge(SENSOR, flow, "u")
    events = events[events["t"] <= duration_s * 1e6]
    times = np.linspace(0, duration_s + 0.1, 101)
    positions = np.stack([SPEED_M_S * times, np.zeros_like(times), np.zeros_like(times)], axis=1)
    quaternions = np.tile([0.0, 0.0, 0.0, 1.0], (len(times), 1))
    write_ecd(folder, events, intrinsics=INTRINSICS, times=times, positions=positions,
              quaternions=quaternions, sensor_size=SENSOR)
    return events


@pytest.fixture(scope="module")
def edge_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("edge")
    straight_edge_recording(folder)
    return folder


@pytest.mark.parametrize("backend", ["fixed", "reference"])
def test_a_straight_edge_comes_out_at_its_depth(edge_folder, tmp_path, capsys, backend):
    out = tmp_path / "depth.npz"
    assert main(["run", str(edge_folder), "--out", str(out), "--backend", backend, "--quiet"]) == 0
    depth, meta = read_depth(out)
    width, height = SENSOR
    events = width * height
    # every column but the first (no facilitating neighbour) and the last ones cut by the 1 s crop
    assert len(depth) >= (50 - 1) * height
    assert np.all(np.abs(depth["z"] - DEPTH_M) <= depth_tolerance(20, 0) + 1e-12)
    assert meta["latency_steps"] == 2 and meta["timestep_us"] == 1000
    printed = capsys.readouterr().out
    assert f"backend        {backend}" in printed
    assert "events in" in printed and "depth out" in printed and "wall time" in printed
    assert meta["summary"]["events_in"] <= events


def test_summary_accounts_for_every_event_and_writes_json(edge_folder, tmp_path):
    out, summary_file = tmp_path / "depth.csv", tmp_path / "run.json"
    assert main(["run", str(edge_folder), "--out", str(out), "--json", str(summary_file), "--quiet"]) == 0
    summary = json.loads(summary_file.read_text())
    assert summary["events_in"] == summary["accepted"] + sum(summary["dropped"].values())
    assert out.read_text().splitlines()[0] == "t,x,y,z,step"
    assert len(out.read_text().splitlines()) == summary["depth_out"] + 2  # header and end line


def test_spec_and_overrides_are_applied(edge_folder, tmp_path, capsys):
    out = tmp_path / "depth.npz"
    assert main(["run", str(edge_folder), "--spec", "examples/paper_distance2.yaml", "--out", str(out),
                 "--quiet"]) == 0
    depth, _ = read_depth(out)
    # distance 2: the counter spans two pixels (40 steps), td = 40 ms / 2 px
    assert np.all(np.abs(depth["z"] - DEPTH_M) <= depth_tolerance(40, 0) + 1e-12)
    # a constant velocity twice as fast as the truth halves nothing but doubles the depth
    assert main(["run", str(edge_folder), "--out", str(out), "--velocity", "1.0,0,0", "--quiet", "--force"]) == 0
    depth, _ = read_depth(out)
    assert np.median(depth["z"]) == pytest.approx(2 * DEPTH_M, rel=1e-3)


def test_pixels_outside_the_sensor_are_counted_and_reported(edge_folder, tmp_path, capsys):
    out = tmp_path / "depth.npz"
    # the edge starts at column 239 and moves left: columns 200..239 lie outside a 200 px wide sensor
    assert main(["run", str(edge_folder), "--sensor-size", "200x180", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "outside the 200x180 sensor" in printed
    _, meta = read_depth(out)
    assert meta["summary"]["dropped"]["out_of_bounds"] == 40 * 180


def test_sensor_size_of_a_file_that_does_not_say_it_is_used_without_the_extent_note(edge_folder, tmp_path, capsys):
    """--sensor-size on a file without a size (an EVT3 header without geometry): the network runs at it and no
    note says the size was taken from the events' extent."""
    from optional import optional
    optional("faery")
    assert main(["convert", str(edge_folder), str(tmp_path / "rec.raw"), "--quiet"]) == 0
    from formats_helpers import strip_geometry
    strip_geometry(tmp_path / "rec.raw", tmp_path / "bare.raw")
    common = ["run", str(tmp_path / "bare.raw"), "--velocity", "0.5,0,0", "--intrinsics", "200,200,119.5,89.5",
              "--quiet", "--force", "--out", str(tmp_path / "d.npz")]
    assert main(common) == 0
    assert "240x180 taken from the events' extent (pass --sensor-size to set it)" in capsys.readouterr().out
    assert main(common + ["--sensor-size", "200x180"]) == 0
    printed = capsys.readouterr().out
    assert "events' extent" not in printed and "(200x180 px," in printed, printed
    _, meta = read_depth(tmp_path / "d.npz")
    assert meta["summary"]["dropped"]["out_of_bounds"] == 40 * 180


def one_line_error(capsys, argv):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    return err


def test_bad_input_gets_one_line_naming_the_problem(edge_folder, tmp_path, capsys):
    assert "no/such/folder" in one_line_error(capsys, ["run", "no/such/folder"])
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "events.txt").write_text("0.001 1 2 1\n0.002 3 x 1\n")
    err = one_line_error(capsys, ["run", str(bad)])
    assert "events.txt:2" in err
    (bad / "events.txt").write_text("0.002 1 2 1\n0.001 3 4 1\n")
    assert "events.txt:2" in one_line_error(capsys, ["run", str(bad)])
    (bad / "events.txt").write_text("")
    assert "no events" in one_line_error(capsys, ["run", str(bad)])
    (bad / "events.txt").write_text("0.001 1 2 1\n0.002 2 2 1\n")
    assert "calib.txt" in one_line_error(capsys, ["run", str(bad), "--velocity", "0.5,0,0"])
    assert "available" in one_line_error(capsys, ["run", str(edge_folder), "--backend", "gpu"])
    assert "input.timestep" in one_line_error(capsys, ["run", str(edge_folder), "--timestep", "soon"])


def test_nan_in_the_poses_is_an_error_naming_the_line(edge_folder, tmp_path, capsys):
    folder = tmp_path / "nan"
    straight_edge_recording(folder, duration_s=0.2)
    lines = (folder / "groundtruth.txt").read_text().splitlines()
    number = next(i for i, line in enumerate(lines) if not line.startswith("#")) + 3
    fields = lines[number - 1].split()
    fields[1] = "nan"
    lines[number - 1] = " ".join(fields)
    (folder / "groundtruth.txt").write_text("\n".join(lines) + "\n")
    assert f"groundtruth.txt:{number}" in one_line_error(capsys, ["run", str(folder)])


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_integer_backends_write_byte_identical_depth_files(tmp_path, suffix):
    """Issue 11: the same input gives the same bytes on fixed and multiproc (canonical order, no run facts)."""
    from tofnet.sim.run import simulate
    folder = tmp_path / "rec"
    simulate("slider", folder, duration=0.05, seed=0)
    files = []
    for backend in ("fixed", "multiproc"):
        out = tmp_path / f"{backend}{suffix}"
        assert main(["run", str(folder), "--backend", backend, "--out", str(out), "--quiet"]) == 0
        files.append(out.read_bytes())
    assert len(files[0]) > 1000 and files[0] == files[1]


def test_a_header_that_states_too_small_a_sensor_is_read_at_the_size_given(edge_folder, tmp_path, capsys):
    """An EVT3 header's geometry smaller than its events: refused with the byte and what to do; --sensor-size (run,
    export, info) reads it at the given size, and the events outside a smaller network are counted."""
    from optional import optional
    optional("faery")
    assert main(["convert", str(edge_folder), str(tmp_path / "rec.raw"), "--quiet"]) == 0
    data = (tmp_path / "rec.raw").read_bytes()
    assert b"geometry 240x180" in data or b"width=240;height=180" in data
    small = data.replace(b"geometry 240x180", b"geometry 200x180").replace(b"width=240;height=180",
                                                                         b"width=200;height=180")
    (tmp_path / "small.raw").write_bytes(small)
    common = ["run", str(tmp_path / "small.raw"), "--velocity", "0.5,0,0", "--intrinsics", "200,200,119.5,89.5",
              "--quiet", "--force", "--out", str(tmp_path / "d.npz")]
    assert main(common) == 2
    err = capsys.readouterr().err
    assert "outside the header's 200x180 geometry at byte " in err and "give the sensor's: --sensor-size WxH" in err
    assert main(common + ["--sensor-size", "240x180"]) == 0
    whole, _ = read_depth(tmp_path / "d.npz")
    assert main(["run", str(edge_folder), "--out", str(tmp_path / "e.npz"), "--quiet"]) == 0
    assert len(whole) == len(read_depth(tmp_path / "e.npz")[0]) > 0
    assert main(["export", str(tmp_path / "d.npz"), "--recording", str(tmp_path / "small.raw"), "--sensor-size",
                 "240x180", "--maps", str(tmp_path / "maps")]) == 0
    assert main(["plot", "depthmap", str(tmp_path / "small.raw"), str(tmp_path / "d.npz"), "--out",
                 str(tmp_path / "d.png")]) == 0  # read as far as the run read it (its depth file says so)
    capsys.readouterr()
    assert main(["run", str(edge_folder), "--intrinsics", "200,200,119.5,89.5", "--sensor-size", "100x80", "--out",
                 str(tmp_path / "crop.npz")]) == 0  # a crop of a file that says its size: no doubt about the camera
    assert "principal point" not in capsys.readouterr().err
    from tofnet.io.source import open_recording
    (tmp_path / "big.raw").write_bytes(data.replace(b"geometry 240x180", b"geometry 99999x180")
                                       .replace(b"width=240;height=180", b"width=99999;height=180"))
    with open_recording(tmp_path / "big.raw") as source:  # a size the decoder cannot read: unknown, and said so
        assert source.sensor_size is None
        assert "is not a sensor size (width, height; at most 65535 px a side)" in " | ".join(source.notes)


def test_maps_of_a_csv_say_where_their_windows_start(tmp_path, capsys):
    """A .csv holds no t0: its windows start at the first estimate, which the output says (the .npz of the same run
    starts them at the run's t0, so map k of the two holds other times)."""
    from tofnet.sim.run import simulate
    folder = tmp_path / "rec"
    simulate("slider", folder, duration=0.05, seed=0)
    for suffix in (".npz", ".csv"):
        assert main(["run", str(folder), "--out", str(tmp_path / f"d{suffix}"), "--quiet"]) == 0
    capsys.readouterr()
    first = read_depth(tmp_path / "d.npz")[0]["t"].min()
    assert main(["export", str(tmp_path / "d.csv"), "--maps", str(tmp_path / "m"), "--recording", str(folder)]) == 0
    assert (f"holds no t0: the windows start at its first estimate ({first * 1e-6:.6f} s); the .npz of the same run "
            "starts them at the run's t0") in capsys.readouterr().out
    assert main(["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path / "n")]) == 0
    assert "holds no t0" not in capsys.readouterr().out


def test_the_summarys_time_parts_count_the_files_load_and_add_up_to_the_whole(edge_folder, tmp_path, monkeypatch,
                                                                             capsys):
    """A .npy is loaded and checked whole when opened: that was in no part of the summary's `wall time` line
    (2.109 s network, 0.568 s reading, 0.070 s set-up, 7.645 s in all, ~4.6 s of it checking the columns)."""
    import time

    import tofnet.io.arrays as arrays
    check = arrays.events_from_columns

    def slow_check(*args, **kwargs):  # a large file's load, without writing one
        time.sleep(0.5)
        return check(*args, **kwargs)
    monkeypatch.setattr(arrays, "events_from_columns", slow_check)
    events = straight_edge_recording(tmp_path / "edge")
    np.save(tmp_path / "edge.npy", events)
    summary_file = tmp_path / "s.json"
    assert main(["run", str(tmp_path / "edge.npy"), "--intrinsics", "200,200,119.5,89.5", "--velocity", "0.5,0,0",
                 "--quiet", "--out", str(tmp_path / "d.npz"), "--json", str(summary_file)]) == 0
    summary = json.loads(summary_file.read_text())
    assert summary["read_time_s"] >= 0.5
    parts = summary["wall_time_s"] + summary["read_time_s"] + summary["setup_time_s"] + summary["compile_time_s"]
    assert parts == pytest.approx(summary["total_time_s"], rel=0.02)
    wall = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("wall time"))
    assert f"{summary['read_time_s']:.3f} s reading" in wall and f"{summary['total_time_s']:.3f} s in all" in wall
