"""Event files: ECD events.txt and numpy .npy/.npz, readers, writers and errors."""

from __future__ import annotations

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.events import EVENT_DTYPE, make_events
from tofnet.io.events import read_events_npy, read_events_txt, write_events_npy, write_events_txt

SLIDER_LINES = "0.003811000 96 133 0\n0.003820001 127 171 1\n1.500000000 4 160 0\n"


def _events(n: int = 50, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return make_events(np.sort(rng.integers(0, 10**10, n)), rng.integers(0, 240, n), rng.integers(0, 180, n),
                       rng.integers(0, 2, n))


def _write(tmp_path, text: str, name: str = "events.txt"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_slider_depth_lines(tmp_path):
    events = read_events_txt(_write(tmp_path, SLIDER_LINES))
    assert events.dtype == EVENT_DTYPE
    assert events["t"].tolist() == [3811, 3820, 1500000]
    assert events["x"].tolist() == [96, 127, 4]
    assert events["y"].tolist() == [133, 171, 160]
    assert events["p"].tolist() == [0, 1, 0]


def test_seconds_become_microseconds_exactly_half_away_from_zero(tmp_path):
    # A float64 cannot hold 1468939993.0674165 exactly; the parser must not need to.
    text = "1468939993.0674165 1 2 1\n1468939993.0674174 1 2 1\n1468939993.99999951 0 0 0\n2e-6 0 0 0\n"
    with pytest.raises(DataError, match=":4: time goes back"):
        read_events_txt(_write(tmp_path, text))
    events = read_events_txt(_write(tmp_path, text.replace("2e-6", "1.5e9")))
    assert events["t"].tolist() == [1468939993067417, 1468939993067417, 1468939994000000, 1500000000000000]


def test_half_microseconds_round_away_from_zero_not_to_even(tmp_path):
    # Also: no newline after the last line.
    text = "-0.0000015 0 0 0\n0.0000015 1 2 1\n0.00000249 0 0 0\n0.0000025 1 2 0"
    assert read_events_txt(_write(tmp_path, text))["t"].tolist() == [-2, 2, 2, 3]


def test_comments_blank_lines_crlf_tabs_and_polarity_minus_one(tmp_path):
    text = "# t x y p\r\n\r\n0.5\t1\t2\t-1\r\n  0.6 3 4 1.0  \r\n"
    events = read_events_txt(_write(tmp_path, text))
    assert events["t"].tolist() == [500000, 600000]
    assert events["p"].tolist() == [0, 1]
    assert events["x"].tolist() == [1, 3]


def test_pixels_beyond_the_sensor_are_kept(tmp_path):
    events = read_events_txt(_write(tmp_path, "0.1 5000 4000 1\n"))
    assert (events["x"][0], events["y"][0]) == (5000, 4000)


def test_txt_round_trip_is_exact(tmp_path):
    events = _events()
    events["t"][0] = 0
    path = tmp_path / "out" / "events.txt"
    write_events_txt(path, events, chunk=7)
    assert np.array_equal(read_events_txt(path), events)
    first = path.read_text().splitlines()[0]
    assert first == f"0.000000000 {events['x'][0]} {events['y'][0]} {events['p'][0]}"


@pytest.mark.parametrize("text, line, message", [
    ("0.1 1 2 0\n0.2 1 2\n", 2, "expected 4 columns"),
    ("0.1 1 2 0\n0.2 1 2 -1 x\n0.3 1 2 1 \n0.4 5 6\n", 4, "found 3 column"),
    ("0.1 1 2 0\nabc 1 2 0\n", 2, "column 't': expected a number, got 'abc'"),
    ("0.1 1 y 0\n", 1, "column 'y': expected a number"),
    ("0.1 1.5 2 0\n", 1, "column 'x': expected a whole number"),
    ("0.1 -3 2 0\n", 1, "column 'x': pixel coordinates must be >= 0"),
    ("0.1 3 -2 0\n", 1, "column 'y': pixel coordinates must be >= 0"),
    ("0.1 70000 2 0\n", 1, "at most 65535"),
    ("0.1 1 2 0\n0.2 1 2 2\n", 2, "polarity must be 0 or 1"),
    ("0.1 1 2 0\n0.3 1 2 0\n\n0.2 1 2 1\n", 4, "time goes back: t = 0.2 s is earlier than the previous event \\(line 2\\)"),
    ("1e400 1 2 0\n", 1, "out of range"),
    ("nan 1 2 0\n", 1, "expected a number"),
])
def test_malformed_lines_name_file_and_line(tmp_path, text, line, message):
    path = _write(tmp_path, text)
    with pytest.raises(DataError, match=f"events.txt:{line}: .*{message}") as info:
        read_events_txt(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n"])
def test_no_events_is_an_error(tmp_path, text):
    with pytest.raises(DataError, match="events.txt: no events"):
        read_events_txt(_write(tmp_path, text))


def test_missing_file_is_a_data_error(tmp_path):
    with pytest.raises(DataError, match="missing.txt: file not found"):
        read_events_txt(tmp_path / "missing.txt")


@pytest.mark.parametrize("name", ["ev.npy", "ev.npz"])
def test_npy_round_trip(tmp_path, name):
    events = _events()
    write_events_npy(tmp_path / name, events)
    loaded = read_events_npy(tmp_path / name)
    assert loaded.dtype == EVENT_DTYPE
    assert np.array_equal(loaded, events)


def test_npz_float_t_is_seconds_and_int_t_is_microseconds(tmp_path):
    np.savez(tmp_path / "f.npz", t=np.array([0.5, 1.0000015]), x=np.array([1, 2]), y=np.array([3, 4]),
             p=np.array([-1, 1]))
    np.savez(tmp_path / "i.npz", t=np.array([500000, 1000002]), x=np.array([1, 2]), y=np.array([3, 4]),
             p=np.array([False, True]))
    seconds = read_events_npy(tmp_path / "f.npz")
    micros = read_events_npy(tmp_path / "i.npz")
    assert seconds["t"].tolist() == [500000, 1000002]
    assert micros["t"].tolist() == [500000, 1000002]
    assert seconds["p"].tolist() == micros["p"].tolist() == [0, 1]


def test_npz_structured_under_events_key_and_npy_columns(tmp_path):
    other = np.zeros(2, dtype=[("x", "<i4"), ("y", "<i4"), ("t", "<f8"), ("p", "i1")])
    other["t"], other["x"], other["y"], other["p"] = (0.25, 0.5), (7, 8), (9, 10), (1, 0)
    np.savez(tmp_path / "s.npz", events=other)
    np.save(tmp_path / "c.npy", np.array([[0.25, 7, 9, 1], [0.5, 8, 10, 0]]))
    for name in ("s.npz", "c.npy"):
        events = read_events_npy(tmp_path / name)
        assert events["t"].tolist() == [250000, 500000]
        assert events["x"].tolist() == [7, 8] and events["y"].tolist() == [9, 10]
        assert events["p"].tolist() == [1, 0]


@pytest.mark.parametrize("columns, message", [
    (dict(t=[0.1, 0.05], x=[1, 1], y=[1, 1], p=[0, 1]), "field 't', event 1: time goes back"),
    (dict(t=[0.1, 0.2], x=[1, -1], y=[1, 1], p=[0, 1]), "field 'x', event 1: pixel coordinates must be >= 0"),
    (dict(t=[0.1, 0.2], x=[1, 1], y=[1, 1.5], p=[0, 1]), "field 'y', event 1: expected a whole number"),
    (dict(t=[0.1, 0.2], x=[1, 1], y=[1, 1], p=[0, 3]), "field 'p', event 1: polarity must be 0 or 1"),
    (dict(t=[0.1, np.nan], x=[1, 1], y=[1, 1], p=[0, 1]), "field 't', event 1: expected a finite number"),
    (dict(t=[], x=[], y=[], p=[]), "no events"),
    (dict(t=[1, 2], x=[1], y=[1, 1], p=[0, 1]), "1-D arrays of one length"),
])
def test_npz_errors_name_file_field_and_event(tmp_path, columns, message):
    np.savez(tmp_path / "bad.npz", **{k: np.asarray(v) for k, v in columns.items()})
    with pytest.raises(DataError, match=f"bad.npz: .*{message}"):
        read_events_npy(tmp_path / "bad.npz")


def test_npz_without_event_arrays_and_corrupt_file(tmp_path):
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(DataError, match="other.npz: expected a structured array 'events' or arrays 't'"):
        read_events_npy(tmp_path / "other.npz")
    (tmp_path / "junk.npy").write_bytes(b"not numpy at all")
    with pytest.raises(DataError, match="junk.npy: not a readable .npy/.npz file"):
        read_events_npy(tmp_path / "junk.npy")
    np.save(tmp_path / "shape.npy", np.zeros((3, 3)))
    with pytest.raises(DataError, match=r"shape.npy: the array has shape \(3, 3\)"):
        read_events_npy(tmp_path / "shape.npy")


@pytest.mark.parametrize("p, got", [([-1, 1], "-1"), ([0, 2], "2"), ([1, 0.5], "0.5")])
def test_make_events_refuses_a_polarity_other_than_0_or_1_as_the_writers_do(tmp_path, p, got):
    """``make_events(..., p=[-1, 1])`` cast -1 to 255, which every kernel then ran as ON."""
    with pytest.raises(DataError, match=f"^polarity must be 0 or 1, got {got}$"):
        make_events([0, 1], [1, 1], [1, 1], p)
    events = make_events([0, 1], [1, 1], [1, 1], [0, 1])
    events["p"][0] = 255
    with pytest.raises(DataError, match="^polarity must be 0 or 1, got 255$"):
        write_events_npy(tmp_path / "e.npy", events)
    assert make_events([0, 1], [1, 1], [1, 1], [True, False])["p"].tolist() == [1, 0]
