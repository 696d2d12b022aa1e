"""Issue 11 regressions, inputs: every bad value, spec and file gets one line; nothing invalid is accepted.

One test per defect found by the fuzzing of issue 11 (outside the backends); the
property-based suite is tests/test_fuzz.py. The guarantees are in docs/reliability.md.
"""

from __future__ import annotations

import os
import socket
import time
import zipfile

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError, SpecError, TofnetError
from tofnet.events import MAX_TIME_US, make_events
from tofnet.io import npy, read_recording
from tofnet.io.ecd import read_gt_depth, write_ecd
from tofnet.io.events import events_from_columns, read_events_npy, read_events_txt
from tofnet.io.groundtruth import Trajectory, quaternion_to_matrix, read_velocity_samples
from tofnet.io.recording import Intrinsics
from tofnet.io.spec import default_spec_path, load_spec

PAPER = default_spec_path().read_text()


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A tiny ECD folder: three events, calibration, two poses."""
    path = tmp_path_factory.mktemp("rec")
    events = make_events([0, 1000, 2000], [1, 2, 3], [1, 1, 1], [1, 1, 1])
    write_ecd(path, events, intrinsics=Intrinsics(200.0, 200.0, 119.5, 89.5), times=[0.0, 1.0],
              positions=[[0, 0, 0], [0.5, 0, 0]], quaternions=[[0, 0, 0, 1], [0, 0, 0, 1]], sensor_size=(240, 180))
    return path


def one_line_error(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


# ---------------------------------------------------------------- CLI values out of range

@pytest.mark.parametrize("option, value, expected", [
    ("--timestep", "1e300", "input.timestep: expected at most 3600 s"),
    ("--timestep", "9.3e12", "input.timestep: expected at most 3600 s"),
    ("--timestep", "nan", "input.timestep"),
    ("--refractory", "1e30", "input.refractory: expected at most 3600 s"),
    ("--distance", "1000000000000", "time_of_travel.distance: expected at most 255"),
    ("--update-every", "10000000000000000000000", "velocity.update_every: expected at most"),
    ("--sensor-size", "100000x100000", "--sensor-size: each side must be at most 65536 px"),
    ("--sensor-size", "65536x65536", "--sensor-size: at most 16,777,216 pixels"),
    ("--velocity", "1e400,0,0", "velocity.velocity: expected a finite number"),
    ("--velocity", "0.5,0", "velocity.velocity: expected three numbers"),
    ("--workers", "-1", "expected a whole number of workers >= 0"),
    ("--patch", "0x5", "--patch"),
])
def test_cli_values_out_of_range_are_one_line(folder, tmp_path, capsys, option, value, expected):
    err = one_line_error(capsys, ["run", str(folder), "--out", str(tmp_path / "d.npz"), option, value, "--quiet"])
    assert expected in err and f"tofnet run: error: {option}: " in err  # named by the option typed
    assert not (tmp_path / "d.npz").exists()


@pytest.mark.parametrize("option, value, expected", [("--duration", "1e300", "duration: expected at most 3600 s"),
                                                     ("--seed", "-1", "seed: expected a whole number >= 0"),
                                                     ("--sensor-size", "8192x8192", "at most 16,777,216 pixels")])
def test_simulate_options_out_of_range(tmp_path, capsys, option, value, expected):
    assert expected in one_line_error(capsys, ["simulate", "slider", str(tmp_path / "s"), option, value, "--quiet"])
    assert not (tmp_path / "s" / "events.txt").exists()


def test_an_overlong_path_is_shortened_in_messages(folder, capsys):
    err = one_line_error(capsys, ["run", str(folder), "--spec", "9" * 5000])
    assert len(err) < 400 and "..." in err


def test_a_newline_in_a_path_stays_on_one_line(folder, capsys):
    assert "\\r\\n: cannot read the spec" in one_line_error(capsys, ["run", str(folder), "--spec", "\r\n"])


def test_spec_option_naming_a_missing_file(folder, capsys):
    assert "nosuchfile: cannot read the spec: file not found" in one_line_error(
        capsys, ["run", str(folder), "--spec", "nosuchfile"])
    with pytest.raises(SpecError, match="no such spec file"):
        load_spec("nosuchfile")


# ---------------------------------------------------------------- spec values

@pytest.mark.parametrize("old, field", [("distance: 1", "distance"), ("counter_bits: 8", "counter_bits"),
                                        ("timestep: 1ms", "timestep"), ("refractory: 60ms", "refractory"),
                                        ("max_depth: 20", "max_depth")])
@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf", "1e300", "1" + "0" * 4000, "9" * 5000])
def test_non_finite_huge_and_overlong_spec_numbers(old, field, value):
    text = PAPER.replace(old, f"{field}: {value}")
    if field == "max_depth" and value == "1e300":
        assert load_spec(text).network.process("depth").max_depth == 1e300  # finite: allowed, rejections counted
        return
    with pytest.raises(SpecError) as info:
        load_spec(text)
    assert "\n" not in str(info.value) and len(str(info.value)) < 200


@pytest.mark.parametrize("value", [".nan", ".inf", "1e300"])
def test_t0_and_budget_numbers(value):
    with pytest.raises(SpecError, match="processes.input.t0"):
        load_spec(PAPER.replace("refractory: 60ms}", f"refractory: 60ms, t0: {value}}}"))
    with pytest.raises(SpecError, match="compile.budget.core.accumulators"):
        load_spec(PAPER.replace("budget: loihi2}", f"budget: {{core: {{accumulators: {value}}}}}}}"))
    with pytest.raises(SpecError, match="compile.budget.max_chips"):
        load_spec(PAPER.replace("budget: loihi2}", f"budget: {{max_chips: {value}}}}}"))


@pytest.mark.parametrize("intrinsics", ["[.nan, 200, 120, 90]", "[0, 200, 120, 90]", "[200, -1, 120, 90]",
                                        "[200, 200, .inf, 90]", "[200, 200, 120]"])
def test_bad_intrinsics_in_a_spec_are_refused(intrinsics):
    with pytest.raises(SpecError, match="intrinsics"):
        load_spec(PAPER.replace("update_every: 1}", f"update_every: 1, intrinsics: {intrinsics}}}"))


def test_nan_max_depth_is_refused():
    with pytest.raises(SpecError, match="max_depth: expected a finite number"):
        load_spec(PAPER.replace("max_depth: 20", "max_depth: .nan"))


@pytest.mark.parametrize("name", ["null", "5", "'a b'", "~"])
def test_process_names_must_be_identifiers(name):
    with pytest.raises(SpecError, match="a process name must be an identifier"):
        load_spec(PAPER.replace("  depth:  ", f"  {name}:  "))


def _laughs(levels: int = 9) -> str:
    text = "a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n"
    for i in range(1, levels + 1):
        text += f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]\n"
    return text


@pytest.mark.parametrize("text, message", [
    ("a: &a [*a]\n", "recursive alias"),
    ("a: &a {b: *a}\n", "recursive alias"),
    ("a: " + "[" * 50_000 + "]" * 50_000 + "\n", "nested more than 32 levels"),
    ("a: " + "{a: " * 2000 + "1" + "}" * 2000 + "\n", "nested more than 32 levels"),
    (_laughs(), "expands to more than 100,000 values"),
    ("x: &x [1]\n" + "".join(f"k{i}: *x\n" for i in range(101)), "more than 100 aliases"),
    ("!!python/object/apply:os.system ['touch /tmp/tofnet-pwned']\n", "is not allowed"),
    ("!!python/object:os.system {a: 1}\n", "is not allowed"),
    ("name: !custom value\n", "tag '!custom' is not allowed"),
    ("name: !!binary aGVsbG8=\n", "is not allowed"),
    ("a: " + "x" * (1 << 20) + "\n", "a spec may hold at most"),
])
def test_hostile_yaml_is_refused_quickly_and_runs_nothing(text, message):
    started = time.perf_counter()
    with pytest.raises(SpecError, match=message) as info:
        load_spec(text)
    assert time.perf_counter() - started < 10
    assert "\n" not in str(info.value) and not os.path.exists("/tmp/tofnet-pwned")


# ---------------------------------------------------------------- .npy / .npz

def _npy_bytes(array) -> bytes:
    import io
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def test_npy_header_with_a_huge_shape_is_refused_before_allocating(tmp_path):
    raw = _npy_bytes(np.zeros(4, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")]))
    header_end = raw.index(b"\n") + 1
    header = raw[10:header_end].replace(b"(4,)", b"(999999999999999,)")
    patched = raw[:8] + len(header).to_bytes(2, "little") + header + raw[header_end:]
    (tmp_path / "ev.npy").write_bytes(patched)
    with pytest.raises(DataError, match="is truncated: the header declares"):
        read_events_npy(tmp_path / "ev.npy")
    (tmp_path / "events_depth.npy").write_bytes(patched)
    with pytest.raises(DataError, match="is truncated"):
        read_gt_depth(tmp_path / "events_depth.npy", 4)


@pytest.mark.parametrize("header", [b"{'descr': '<i8', 'fortran_order': False, 'shape': (3,), '''",
                                    b"{'descr': '<i8', 'fortran_order': False, 'shape': ((((((3,)",
                                    b"{'descr': 'O', 'fortran_order': False, 'shape': (3,), }",
                                    b"\xff\xfe garbage", b"[1, 2, 3]"])
def test_corrupt_npy_headers_are_one_line(tmp_path, header):
    header = header.ljust(118) + b"\n"
    (tmp_path / "bad.npy").write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + bytes(24))
    with pytest.raises(DataError) as info:
        read_events_npy(tmp_path / "bad.npy")
    assert "\n" not in str(info.value)


def test_truncated_npz_and_bad_crc_are_refused(tmp_path):
    events = make_events(np.arange(1000), np.zeros(1000), np.zeros(1000), np.ones(1000))
    np.savez(tmp_path / "ev.npz", **{k: events[k] for k in "txyp"})
    raw = (tmp_path / "ev.npz").read_bytes()
    for cut in (10, len(raw) // 2, len(raw) - 5):
        (tmp_path / "cut.npz").write_bytes(raw[:cut])
        with pytest.raises(DataError):
            read_events_npy(tmp_path / "cut.npz")
    flipped = bytearray(raw)
    flipped[raw.index(events["t"].tobytes()) + 100] ^= 0xFF
    (tmp_path / "crc.npz").write_bytes(bytes(flipped))
    with pytest.raises(DataError, match="Bad CRC-32"):
        read_events_npy(tmp_path / "crc.npz")


def test_zip_errors_do_not_quote_the_archive(tmp_path):
    # Found by benchmarks/fuzz.py: zipfile's message quoted a whole local header.
    np.savez(tmp_path / "ev.npz", t=np.arange(3), x=np.zeros(3), y=np.zeros(3), p=np.ones(3))
    raw = bytearray((tmp_path / "ev.npz").read_bytes())
    local = raw.index(b"x.npy")  # the local header's name of member x
    raw[local] = ord("q")
    (tmp_path / "ev.npz").write_bytes(bytes(raw))
    with pytest.raises(DataError, match="File name in directory") as info:
        read_events_npy(tmp_path / "ev.npz")
    assert len(str(info.value)) < 250


def test_zip_bomb_is_refused_by_its_declared_size(tmp_path, monkeypatch):
    monkeypatch.setattr(npy, "MAX_INFLATED_BYTES", 1 << 20)  # the real limit is 256 MiB
    with zipfile.ZipFile(tmp_path / "bomb.npz", "w", zipfile.ZIP_DEFLATED) as archive:
        for name in "txyp":
            archive.writestr(f"{name}.npy", _npy_bytes(np.zeros(4 << 20, dtype=np.uint8)))
    assert (tmp_path / "bomb.npz").stat().st_size < 100_000
    with pytest.raises(DataError, match="a zip bomb"):
        read_events_npy(tmp_path / "bomb.npz")


# ---------------------------------------------------------------- values that used to be accepted

def test_integer_times_outside_the_documented_range():
    cols = {"x": [0, 0], "y": [0, 0], "p": [0, 0]}
    with pytest.raises(DataError, match="event 0: 9223372036854775808 µs is out of range"):
        events_from_columns({"t": np.array([2**63, 2**63 + 1], dtype=np.uint64), **cols})
    with pytest.raises(DataError, match="out of range"):
        events_from_columns({"t": np.array([9 * 10**18, -9 * 10**18]), **cols})
    with pytest.raises(DataError, match="out of range"):
        events_from_columns({"t": np.array([0.0, 2.4e12]), **cols})
    with pytest.raises(DataError, match="field 't': expected numbers, got dtype bool"):
        events_from_columns({"t": np.array([False, True]), **cols})
    edge = events_from_columns({"t": np.array([-(MAX_TIME_US - 1), MAX_TIME_US - 1]), **cols})
    assert edge["t"].tolist() == [-(MAX_TIME_US - 1), MAX_TIME_US - 1]


def test_events_txt_digits_beyond_int64_are_exact_and_rounding_is_reported(tmp_path):
    (tmp_path / "events.txt").write_text("65535.0000000000000000001 1 2 1\n"
                                         "1234567890123.45678949999999999999 1 1 1\n"
                                         "1234567890123.4567895 1 1 1\n"
                                         "2305843009213.693951 0 0 0\n")
    notes: list[str] = []
    events = read_events_txt(tmp_path / "events.txt", notes)
    assert events["t"].tolist() == [65535000000, 1234567890123456789, 1234567890123456790, MAX_TIME_US - 1]
    assert notes == ["events.txt: 3 time(s) had digits below 1 µs; rounded to the nearest µs, halves away from zero"]
    assert "rounded to the nearest µs" in read_recording(tmp_path).notes[0]
    (tmp_path / "events.txt").write_text("2305843009213.693952 0 0 0\n")
    with pytest.raises(DataError, match=":1: column 't': time 2305843009213.693952 s is out of range"):
        read_events_txt(tmp_path / "events.txt")
    (tmp_path / "events.txt").write_text("1 1.00000000000000000000000001 0 0\n")
    with pytest.raises(DataError, match="column 'x': expected a whole number"):
        read_events_txt(tmp_path / "events.txt")


@pytest.mark.parametrize("value", [np.inf, -1.0, 0.0, -np.inf])
def test_true_depths_must_be_positive_and_finite(tmp_path, value):
    np.save(tmp_path / "events_depth.npy", np.array([1.0, np.nan, value]))
    with pytest.raises(DataError, match="event 2: true depth"):
        read_gt_depth(tmp_path / "events_depth.npy", 3)


def test_huge_quaternions_normalise_and_only_zero_is_refused():
    q = np.array([[0, 0, 0, 1e200], [0, 0, 1e200, 1e200]])
    trajectory = Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]], q)
    assert np.allclose(quaternion_to_matrix(trajectory.quaternions[1])[0], [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    small = Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]], [[0, 0, 0, 1e-6], [0, 0, 0, 1]])
    assert np.allclose(small.quaternions[0], [0, 0, 0, 1])
    for zero in ([0, 0, 0, 0], [0, 0, 1e-200, 0]):  # a norm below 1e-12 counts as zero
        with pytest.raises(DataError, match="pose 0: quaternion qx qy qz qw is zero"):
            Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]], [zero, [0, 0, 0, 1]])
    with pytest.raises(DataError, match="velocity to this pose overflows"):
        Trajectory([0.0, 1e-300], [[0, 0, 0], [1e300, 0, 0]], [[0, 0, 0, 1], [0, 0, 0, 1]])


# ---------------------------------------------------------------- hangs and blow-ups

def test_a_huge_sensor_size_file_is_refused_fast(folder, tmp_path, capsys):
    big = tmp_path / "big"
    big.mkdir()
    (big / "events.txt").write_text((folder / "events.txt").read_text())
    (big / "sensor_size.txt").write_text("100000 100000\n")
    started = time.perf_counter()
    assert "sensor size: each side must be at most 65536 px" in one_line_error(capsys, ["run", str(big)])
    assert time.perf_counter() - started < 30


def test_the_compiler_refuses_sensors_and_core_counts_beyond_its_limits():
    from tofnet.compiler import compile_network
    from tofnet.errors import BudgetError
    from tofnet.networks import depth_network
    with pytest.raises(TofnetError, match="at most 16,777,216 pixels"):
        depth_network((8192, 8192))
    started = time.perf_counter()
    with pytest.raises(BudgetError, match="at most 65,536 per layer"):
        compile_network(depth_network((1280, 720)), patch=(1, 1))
    assert time.perf_counter() - started < 5


def test_non_regular_files_are_refused_not_read(tmp_path):
    os.mkfifo(tmp_path / "fifo.txt")
    with pytest.raises(DataError, match="is a FIFO"):
        read_events_txt(tmp_path / "fifo.txt")
    with pytest.raises(DataError, match="is a character device"):
        read_events_npy("/dev/zero")
    with pytest.raises(DataError, match="is a folder"):
        read_events_txt(tmp_path)
    server = socket.socket(socket.AF_UNIX)
    try:
        server.bind(str(tmp_path / "sock.npy"))
        with pytest.raises(DataError, match="is a socket|cannot open"):
            read_events_npy(tmp_path / "sock.npy")
    finally:
        server.close()
    (tmp_path / "rec").mkdir()
    os.mkfifo(tmp_path / "rec" / "events.txt")
    with pytest.raises(DataError, match="is a FIFO"):
        read_recording(tmp_path / "rec")
    (tmp_path / "rec" / "events.txt").unlink()
    (tmp_path / "rec" / "events.txt").write_text("0.001 1 2 1\n")
    os.mkfifo(tmp_path / "rec" / "calib.txt")
    with pytest.raises(DataError, match="calib.txt: is a FIFO"):
        read_recording(tmp_path / "rec")
    with pytest.raises(SpecError, match="cannot read the spec: is a character device"):
        load_spec(__import__("pathlib").Path("/dev/zero"))


# ---------------------------------------------------------------- what errors quote

def test_errors_quote_only_the_offending_field(tmp_path):
    secret = "root:x:0:0:SECRET-VALUE:/root:/bin/bash"
    (tmp_path / "passwd").write_text(secret + "\ndaemon:x:1:1::/:/bin/sh\n")
    for read in (read_velocity_samples, read_events_txt):
        with pytest.raises(DataError) as info:
            read(tmp_path / "passwd")
        assert "SECRET" not in str(info.value) and "0:0" not in str(info.value)
    (tmp_path / "ev.txt").write_text("0.1 1 2 " + "9" * 10_000 + "\n")
    with pytest.raises(DataError) as info:
        read_events_txt(tmp_path / "ev.txt")
    assert len(str(info.value)) < 200
    with pytest.raises(TofnetError) as info:
        load_spec(PAPER.replace("distance: 1", "distance: " + "1" * 4000))
    assert len(str(info.value)) < 200
