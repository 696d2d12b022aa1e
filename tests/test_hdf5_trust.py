"""Issue 27 item 3: HDF5 files whose data is elsewhere or not there at all, refused in one line.

External raw storage (any file, a FIFO, /dev/zero), virtual datasets (a missing source read
as t = 0), external links, 10^12 declared but unallocated events, a group where a dataset
is expected, MVSEC ground-truth timestamps unsorted or NaN. Fixtures are written by h5py.
"""

import os
import signal
import time
from contextlib import contextmanager

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.io import read_recording
from optional import optional

h5py = optional("h5py")

from formats_helpers import SENSOR, pattern_recording  # noqa: E402

EVENTS = pattern_recording(duration_us=50_000).events
COLUMNS = {"t": EVENTS["t"].astype("<i8"), "x": EVENTS["x"], "y": EVENTS["y"], "p": EVENTS["p"]}


@contextmanager
def deadline(seconds=20):
    """A read that blocks (a FIFO as storage) fails the test instead of hanging it."""
    def expired(*_):
        raise TimeoutError("blocked")
    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def refused(path, match, **options):
    with deadline(), pytest.raises(DataError) as caught:
        read_recording(path, **options)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message, message
    assert match in message, message
    return message


def dsec(path, *, external=None, declared=None, skip=(), group_for=None):
    """A DSEC-layout file; ``external``: name -> raw file holding that column; ``declared``: every
    column declared with that many events and nothing written; ``group_for``: a column made a group."""
    with h5py.File(path, "w") as f:
        for name, data in COLUMNS.items():
            if name in skip:
                continue
            if name == group_for:
                f.create_group(f"events/{name}")
            elif declared is not None:
                f.create_dataset(f"events/{name}", shape=(declared,), dtype=data.dtype, chunks=(1 << 16,))
            elif external and name in external:
                data.tofile(external[name])
                f.create_dataset(f"events/{name}", shape=data.shape, dtype=data.dtype,
                                 external=[(external[name].name, 0, data.nbytes)])
            else:
                f.create_dataset(f"events/{name}", data=data)
        f.create_dataset("t_offset", data=np.int64(0))


def test_external_storage_is_refused_unless_allowed_and_then_read(tmp_path, monkeypatch):
    """It read any local file's bytes as event times."""
    path = tmp_path / "events.h5"
    dsec(path, external={"t": tmp_path / "t.raw"})
    monkeypatch.chdir("/")  # libhdf5 would look in the working folder; tofnet looks next to the file
    message = refused(path, "external raw storage")
    assert "events/t" in message and "--allow-external" in message
    assert np.array_equal(read_recording(path, allow_external=True).events, EVENTS)


@pytest.mark.parametrize("storage", ["fifo", "/dev/zero", "short", "missing", "elsewhere"])
def test_external_storage_that_is_not_a_regular_file_holding_the_data_is_refused_even_when_allowed(tmp_path, storage):
    """A FIFO blocked forever; /dev/zero read as t = 0 (a link to it is outside the folder now, refused as
    such: a device in the folder is refused by open_regular, tests/test_reliability_inputs.py); a file
    outside the HDF5 file's folder (a file from someone else naming one of yours) is refused even when
    it holds the bytes."""
    path = tmp_path / "events.h5"
    target = tmp_path / "t.raw"
    if storage == "elsewhere":
        (tmp_path / "other").mkdir()
        target = tmp_path / "other" / "t.raw"
        target.write_bytes(COLUMNS["t"].tobytes())
        path = tmp_path / "h5" / "events.h5"
        path.parent.mkdir()
    if storage == "fifo":
        os.mkfifo(target)
    elif storage == "/dev/zero":
        target.symlink_to("/dev/zero")
    elif storage == "short":
        target.write_bytes(b"\0" * 100)
    with h5py.File(path, "w") as f:
        for name, data in COLUMNS.items():
            if name == "t":
                f.create_dataset("events/t", shape=data.shape, dtype=data.dtype,
                                 external=[(str(target) if storage == "elsewhere" else target.name, 0,
                                            data.nbytes)])
            else:
                f.create_dataset(f"events/{name}", data=data)
    expected = {"fifo": "FIFO", "/dev/zero": "outside this file's folder", "short": "its files hold 100",
                "missing": "file not found", "elsewhere": "outside this file's folder"}[storage]
    started = time.monotonic()
    refused(path, expected, allow_external=True)
    refused(path, "refused unless --allow-external")
    assert time.monotonic() - started < 10


def _virtual(path, source_name, n=len(EVENTS)):
    layout = h5py.VirtualLayout(shape=(n,), dtype="<i8")
    layout[:] = h5py.VirtualSource(source_name, "t", shape=(n,))
    with h5py.File(path, "w") as f:
        f.create_virtual_dataset("events/t", layout, fillvalue=0)
        for name in ("x", "y", "p"):
            f.create_dataset(f"events/{name}", data=COLUMNS[name])


def test_a_virtual_dataset_is_refused_unless_allowed_and_its_source_must_exist(tmp_path, monkeypatch):
    """A virtual dataset whose source file is missing read as fill values (t = 0)."""
    with h5py.File(tmp_path / "source.h5", "w") as f:
        f.create_dataset("t", data=COLUMNS["t"])
    _virtual(tmp_path / "events.h5", "source.h5")
    monkeypatch.chdir("/")
    assert "virtual dataset" in refused(tmp_path / "events.h5", "refused unless --allow-external")
    assert np.array_equal(read_recording(tmp_path / "events.h5", allow_external=True).events, EVENTS)
    _virtual(tmp_path / "missing.h5", "gone.h5")
    refused(tmp_path / "missing.h5", "file not found", allow_external=True)
    _virtual(tmp_path / "wrong.h5", "source.h5")
    with h5py.File(tmp_path / "source.h5", "w") as f:
        f.create_dataset("other", data=COLUMNS["t"])
    refused(tmp_path / "wrong.h5", "does not exist there", allow_external=True)


def test_an_external_link_to_a_fifo_is_refused_without_opening_it(tmp_path):
    os.mkfifo(tmp_path / "pipe.h5")
    with h5py.File(tmp_path / "events.h5", "w") as f:
        for name, data in COLUMNS.items():
            f.create_dataset(f"events/{name}", data=data)
        f["calib"] = h5py.ExternalLink("pipe.h5", "/calib")
    refused(tmp_path / "events.h5", "external link")
    refused(tmp_path / "events.h5", "FIFO", allow_external=True)


@pytest.mark.parametrize("command", ["run", "info", "convert"])
def test_a_tiny_file_declaring_10_to_the_12_events_is_refused_by_every_command(tmp_path, command, capsys):
    """run/info ground through fill values and convert allocated them all."""
    path = tmp_path / "events.h5"
    dsec(path, declared=10**12)
    assert path.stat().st_size < 20_000
    args = {"run": ["run", str(path), "--velocity", "0.5,0,0", "--out", str(tmp_path / "d.npz")],
            "info": ["info", str(path)], "convert": ["convert", str(path), str(tmp_path / "out.npz")]}[command]
    started = time.monotonic()
    with deadline(60):
        assert main(args + ["--quiet"]) == 2
    assert time.monotonic() - started < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "declares shape (1000000000000,)" in err[0] and "chunks are written" in err[0], err


def test_contiguous_and_compressed_declarations_are_checked_too(tmp_path):
    path = tmp_path / "events.h5"
    with h5py.File(path, "w") as f:
        for name, data in COLUMNS.items():
            if name == "t":
                f.create_dataset("events/t", shape=(10**12,), dtype="<i8")  # contiguous, never written
            else:
                f.create_dataset(f"events/{name}", data=data)
    refused(path, "the file holds 0 bytes of it")
    with h5py.File(path, "w") as f:
        for name, data in COLUMNS.items():
            f.create_dataset(f"events/{name}", data=data, compression="gzip")
    assert len(read_recording(path).events) == len(EVENTS)  # a compressed file that is whole is read


def test_a_group_where_a_dataset_is_expected_is_one_line(tmp_path):
    """It was an AttributeError traceback."""
    path = tmp_path / "events.h5"
    dsec(path, group_for="t")
    refused(path, "'events/t': expected a dataset, found a group")
    with h5py.File(tmp_path / "run_data.hdf5", "w") as f:
        f.create_group("davis/left/events/rows")
    refused(tmp_path / "run_data.hdf5", "'davis/left/events': expected a dataset, found a group")
    with h5py.File(tmp_path / "x_data.hdf5", "w") as f:
        f.create_dataset("davis/left/events", data=np.zeros((3, 4)) + [1, 1, 0.001, 1])
        f.create_dataset("davis/right", data=np.zeros(3))  # a dataset where the group of a camera is
    assert len(read_recording(tmp_path / "x_data.hdf5").events) == 3


def _mvsec(folder, depth_times):
    events = EVENTS
    rows = np.column_stack([events["x"], events["y"], events["t"] * 1e-6, np.where(events["p"] == 1, 1.0, -1.0)])
    with h5py.File(folder / "flying_data.hdf5", "w") as f:
        f.create_dataset("davis/left/events", data=rows)
    with h5py.File(folder / "flying_gt.hdf5", "w") as f:
        f.create_dataset("davis/left/depth_image_raw", data=np.full((len(depth_times), SENSOR[1], SENSOR[0]), 2.0))
        start = EVENTS["t"][0] * 1e-6  # depth image times are Unix-epoch seconds, as the events'
        f.create_dataset("davis/left/depth_image_raw_ts", data=start + np.asarray(depth_times, dtype=np.float64))
    return folder / "flying_data.hdf5"


@pytest.mark.parametrize("times, problem", [([0.03, 0.01, 0.02], "strictly increasing"),
                                            ([0.01, np.nan, 0.03], "expected a finite time"),
                                            ([0.01, 0.02, 1e300], "expected a finite time")])
def test_mvsec_depth_image_times_must_be_finite_and_sorted(tmp_path, times, problem):
    """Unsorted or NaN depth_image_raw_ts gave wrong true depths without an error."""
    path = _mvsec(tmp_path, times)
    with pytest.raises(DataError) as caught:
        read_recording(path)
    message = str(caught.value)
    assert "flying_gt.hdf5" in message and "davis/left/depth_image_raw_ts" in message and problem in message
    assert "\n" not in message
    good = _mvsec(tmp_path, [0.01, 0.02, 0.03])
    assert np.isfinite(read_recording(good).gt_depth).any()


def test_allow_external_on_the_command_line(tmp_path, capsys):
    path = tmp_path / "events.h5"
    dsec(path, external={"t": tmp_path / "t.raw"})
    assert main(["info", str(path), "--quiet"]) == 2
    assert "--allow-external" in capsys.readouterr().err
    assert main(["info", str(path), "--allow-external"]) == 0
    assert main(["convert", str(path), str(tmp_path / "out.npz"), "--allow-external", "--quiet"]) == 0
    assert np.array_equal(read_recording(tmp_path / "out.npz").events, EVENTS)


def test_every_command_reading_the_recording_takes_allow_external(tmp_path, capsys):
    path, depth = tmp_path / "events.h5", tmp_path / "depth.npz"
    dsec(path, external={"t": tmp_path / "t.raw"})
    with h5py.File(path, "a") as f:
        f["calib/resolution"] = np.array(SENSOR)
    run = ["run", str(path), "--velocity", "0.5,0,0", "--intrinsics", "20,20,8,6", "--out", str(depth), "--quiet"]
    assert main(run) == 2 and "--allow-external" in capsys.readouterr().err
    assert main(run + ["--allow-external"]) == 0 and depth.exists()
    for command in (["export", str(depth), "--maps", str(tmp_path / "maps"), "--recording", str(path)],
                    ["eval", str(path), str(depth)], ["plot", "depthmap", str(path), str(depth)]):
        assert main(command) == 2, command
        assert "refused unless --allow-external" in capsys.readouterr().err, command
    assert main(["export", str(depth), "--maps", str(tmp_path / "maps")]) == 2  # the recording the depth file names:
    assert "(DataError); pass --recording PATH to read it and see why" in capsys.readouterr().err  # no quote of it
    assert main(["export", str(depth), "--maps", str(tmp_path / "maps"), "--allow-external"]) == 0
