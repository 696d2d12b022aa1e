"""Depth output files: .npz and .csv round trips and errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.events import DEPTH_DTYPE
from tofnet.io.depth import read_depth, write_depth


def _depth() -> np.ndarray:
    depth = np.empty(4, dtype=DEPTH_DTYPE)
    depth["t"] = [1468939993067417, 1468939993068000, 1468939993068000, 1468939993070000]
    depth["x"] = [0, 17, 239, 65535]
    depth["y"] = [0, 3, 179, 2]
    depth["z"] = [0.1, 1.2345678901234567, 19.99, 0.3]
    depth["step"] = [0, 1, 1, 3]
    return depth


def test_npz_round_trip_with_meta_and_summary(tmp_path):
    depth = _depth()
    summary = {"events_in": np.int64(12), "dropped": {"refractory": 3}, "rate": np.float32(0.5),
               "hist": np.arange(3)}
    write_depth(tmp_path / "d.npz", depth, t0_us=1468939993066000, timestep_us=1000, latency_steps=2,
                summary=summary)
    back, meta = read_depth(tmp_path / "d.npz")
    assert back.dtype == DEPTH_DTYPE and np.array_equal(back, depth)
    assert meta == {"t0_us": 1468939993066000, "timestep_us": 1000, "latency_steps": 2,
                    "summary": {"events_in": 12, "dropped": {"refractory": 3}, "rate": 0.5, "hist": [0, 1, 2]}}
    with np.load(tmp_path / "d.npz") as data:
        assert data["t"].dtype == np.float64 and np.allclose(data["t"], depth["t"] * 1e-6)
        assert data["x"].dtype == np.uint16 and data["step"].dtype == np.int64
        assert json.loads(str(data["summary_json"]))["events_in"] == 12


def test_csv_round_trip(tmp_path):
    depth = _depth()
    write_depth(tmp_path / "d.csv", depth, t0_us=0, timestep_us=1000, latency_steps=2)
    lines = (tmp_path / "d.csv").read_text().splitlines()
    assert lines[0] == "t,x,y,z,step"
    assert lines[1] == "1468939993.067417,0,0,0.1,0"
    assert lines[-1] == "# end: 4 rows"
    back, meta = read_depth(tmp_path / "d.csv")
    assert np.array_equal(back, depth)
    assert meta["t0_us"] is None and meta["summary"] is None


@pytest.mark.parametrize("name", ["e.npz", "e.csv"])
def test_empty_depth_round_trips(tmp_path, name):
    write_depth(tmp_path / name, np.empty(0, dtype=DEPTH_DTYPE), t0_us=0, timestep_us=1000, latency_steps=2)
    back, _ = read_depth(tmp_path / name)
    assert back.shape == (0,) and back.dtype == DEPTH_DTYPE


@pytest.mark.parametrize("text, message", [
    ("t,x,y,z\n1,2,3,4\n", ":1: expected the header 't,x,y,z,step'"),
    ("t,x,y,z,step\n0.1,1,2,3.0,0\n0.2,1,2,3.0\n", ":3: expected 5 columns"),
    ("t,x,y,z,step\n0.1,1,2,3.0,0\n\n0.2,1,b,3.0,1\n", ":4: column 'y': expected a number"),
    ("t,x,y,z,step\n0.1,1,2,3.0,0\n0.2,1.5,2,3.0,1\n", ":3: column 'x': expected a whole number"),
])
def test_csv_errors_name_line(tmp_path, text, message):
    (tmp_path / "d.csv").write_text(text + "# end: 2 rows\n")
    with pytest.raises(DataError, match=f"d.csv{message}"):
        read_depth(tmp_path / "d.csv")


def test_bad_suffix_and_missing_npz_arrays(tmp_path):
    with pytest.raises(DataError, match="d.txt: depth output must be a .npz or .csv file"):
        write_depth(tmp_path / "d.txt", _depth(), t0_us=0, timestep_us=1000, latency_steps=2)
    np.savez(tmp_path / "d.npz", t=np.zeros(2), x=np.zeros(2))
    with pytest.raises(DataError, match="d.npz: missing array\\(s\\) y, z, step"):
        read_depth(tmp_path / "d.npz")
    with pytest.raises(DataError, match="gone.npz: file not found"):
        read_depth(tmp_path / "gone.npz")



@pytest.mark.parametrize("meta, last_step, message", [
    ({"timestep_us": 2**60}, 3, "'timestep_us' must be 1..3600000000 µs (at most 3600 s), got 1152921504606846976"),
    ({"timestep_us": 0}, 3, "'timestep_us' must be 1..3600000000 µs"),
    ({"latency_steps": 2**60}, 3, "'latency_steps' must be 0..1,000,000, got 1152921504606846976"),
    ({"latency_steps": -1}, 3, "'latency_steps' must be 0..1,000,000, got -1"),
    ({"timestep_us": 3_600_000_000}, 700_000_000,  # 700 M hours: beyond 2**61 µs (640 M hours)
     "array 'step' reaches 700000000: 700000000 steps of 3600000000 µs ('timestep_us') lie beyond the time range"),
])
def test_npz_timing_out_of_a_runs_range_names_the_field(tmp_path, meta, last_step, message):
    """eval multiplies steps by the timestep: a timestep or latency of 2**60 (|v| < 2**61 was all that was
    asked) made it allocate hundreds of TiB; each is one line naming the field, when the file is read."""
    depth = _depth()
    depth["step"][-1] = last_step
    write_depth(tmp_path / "d.npz", depth, **{"t0_us": 1468939993066000, "timestep_us": 1000, "latency_steps": 2,
                                              **meta})
    with pytest.raises(DataError) as err:
        read_depth(tmp_path / "d.npz")
    assert str(err.value).startswith(f"{tmp_path / 'd.npz'}: {message}")
    depth["step"][-1] = 3  # an hour's timestep itself is a run's
    write_depth(tmp_path / "ok.npz", depth, t0_us=0, timestep_us=3_600_000_000, latency_steps=1_000_000)
    assert read_depth(tmp_path / "ok.npz")[1]["timestep_us"] == 3_600_000_000


@pytest.mark.parametrize("text, message", [
    ('{"n": ' + "1" * 5000 + "}", "summary_json is not readable JSON (Exceeds the limit (4300 digits)"),  # ValueError
    ("[" * 100_000, "summary_json is nested too deeply"),
    ('{"n": 1', "summary_json is not valid JSON (Expecting ',' delimiter, line 1 column 8)"),
])
def test_a_summary_python_cannot_read_is_one_line(tmp_path, text, message):
    write_depth(tmp_path / "d.npz", _depth(), t0_us=1468939993066000, timestep_us=1000, latency_steps=2)
    arrays = dict(np.load(tmp_path / "d.npz"))
    np.savez(tmp_path / "d.npz", **{**arrays, "summary_json": np.str_(text)})
    with pytest.raises(DataError) as err:
        read_depth(tmp_path / "d.npz")
    assert str(err.value).startswith(f"{tmp_path / 'd.npz'}: {message}")
