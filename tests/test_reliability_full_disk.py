"""Full disks and read-only folders (issue 27, item 4): one line naming the path, no partial
output, never a crash inside h5py or a traceback from the AEDAT4 encoder.

The tests on a real full or read-only file system mount a small tmpfs and skip where
mounting is not permitted; the others make the write fail with ``ENOSPC``.
"""

import contextlib
import errno
import os
import subprocess
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.events import make_events
from tofnet.io.events import write_events_npy
from optional import optional

ROOT = Path(__file__).resolve().parents[1]


def _events(n: int) -> np.ndarray:
    t = np.arange(n, dtype=np.int64) * 10
    return make_events(t, t % 240, (t // 240) % 180, t % 2)


@contextlib.contextmanager
def tmpfs(size: str, *options: str):
    """A fresh tmpfs of ``size`` (skips the test where mounting is not permitted)."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    where = Path(f"/tmp/tofnet-tmpfs-{uuid.uuid4().hex[:8]}")
    where.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", ",".join([f"size={size}", *options]), "tmpfs",
                              str(where)], capture_output=True)
    if mounted.returncode != 0:
        where.rmdir()
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode(errors='replace').strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], capture_output=True)
        with contextlib.suppress(OSError):
            where.rmdir()


def _tofnet(*args: str) -> subprocess.CompletedProcess:
    """``python -m tofnet`` in a child: a crash (SIGSEGV) must not take the test run with it."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "tofnet", *args], capture_output=True, text=True, env=env,
                          timeout=300)


@pytest.mark.parametrize("name", ["out.h5", "out.aedat4", "out_ecd", "out.npz", "out.dat"])
def test_convert_on_a_full_file_system_is_one_line(tmp_path, name):
    optional("h5py" if name.endswith(".h5") else "numpy")
    if name.endswith((".aedat4", ".dat")):
        optional("faery")
    source = tmp_path / "big.npy"
    write_events_npy(source, _events(400_000))  # ~6 MB of events; every output format needs > 2 MB
    with tmpfs("2m") as full:
        done = _tofnet("convert", str(source), str(full / name), "--quiet", "--sensor-size", "240x180")
        assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr[-2000:]
        assert f"{full / name}" in lines[0] and "No space left on device" in lines[0]
        assert sorted(os.listdir(full)) == []  # the partial output is removed


def test_convert_to_a_read_only_file_system_is_refused_before_reading(tmp_path):
    source = tmp_path / "small.npy"
    write_events_npy(source, _events(100))
    with tmpfs("1m", "ro") as read_only:
        done = _tofnet("convert", str(source), str(read_only / "out.h5"), "--quiet")
        assert done.returncode == 2
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"tofnet convert: error: {read_only}: output: ")
        assert "not writable" in lines[0] or "Read-only file system" in lines[0]


def test_a_full_file_system_is_refused_before_the_work(tmp_path, monkeypatch, capsys):
    import shutil

    from tofnet.io import files

    source = tmp_path / "small.npy"
    write_events_npy(source, _events(100))
    monkeypatch.setattr(files.shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 10**9, 0))
    assert main(["convert", str(source), str(tmp_path / "out.h5"), "--quiet"]) == 2
    assert "the file system is full (0 bytes free" in capsys.readouterr().err
    assert not (tmp_path / "out.h5").exists()


class _FillsUp:
    """A raw file that takes ``room`` bytes, then fails with ENOSPC like a full disk."""

    def __init__(self, real, room: int):
        self.real, self.room = real, room

    def write(self, data):
        size = len(memoryview(data).cast("B"))
        if size > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= size
        return self.real.write(data)

    def __getattr__(self, name):
        return getattr(self.real, name)


def test_hdf5_full_disk_while_writing_is_one_line_and_no_file(tmp_path, monkeypatch, capsys):
    optional("h5py")
    from tofnet.io import lenient_file

    source = tmp_path / "big.npy"
    write_events_npy(source, _events(300_000))
    real_open = open
    monkeypatch.setattr(lenient_file, "open", lambda *a, **k: _FillsUp(real_open(*a, **k), 1 << 20), raising=False)
    assert main(["convert", str(source), str(tmp_path / "out.h5"), "--quiet", "--sensor-size", "240x180"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [f"tofnet convert: error: {tmp_path / 'out.h5'}: cannot write: No space left on device"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.npy"]


def test_aedat4_encoder_errors_are_one_line(tmp_path, monkeypatch, capsys):
    optional("faery")
    from faery.extension import aedat

    from formats_helpers import FullDiskEncoder

    monkeypatch.setattr(aedat, "Encoder", FullDiskEncoder)
    source = tmp_path / "small.npy"
    write_events_npy(source, _events(100))
    assert main(["convert", str(source), str(tmp_path / "out.aedat4"), "--quiet", "--sensor-size", "240x180"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [f"tofnet convert: error: {tmp_path / 'out.aedat4'}: cannot write: "
                                "No space left on device"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.npy"]


def test_export_maps_on_a_full_file_system_is_one_line_and_no_folder(tmp_path, monkeypatch, capsys):
    from tofnet.events import DEPTH_DTYPE
    from tofnet.io import files
    from tofnet.io.depth import write_depth

    depth = np.zeros(200, dtype=DEPTH_DTYPE)
    depth["t"], depth["x"], depth["z"] = np.arange(200) * 1000, 1, 1.5
    write_depth(tmp_path / "d.npz", depth, t0_us=0, timestep_us=1000, latency_steps=0)
    options = ["--maps", None, "--window", "1ms", "--sensor-size", "240x180"]
    with tmpfs("2m") as full:  # 200 windows of 240x180 maps need ~70 MB: refused before the first is written
        options[1] = str(full / "maps")
        done = _tofnet("export", str(tmp_path / "d.npz"), *options)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1, done.stderr[-2000:]
        assert f"{full / 'maps'}: --maps: 200 maps of 240x180 px need up to " in lines[0] and "MB free; " in lines[0]
        assert os.listdir(full) == []
        # a file system that does not say (or is filled meanwhile): the write fails, the partial folder is removed
        monkeypatch.setattr(files, "free_bytes", lambda path: None)
        assert main(["export", str(tmp_path / "d.npz"), *options]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and f"{full / 'maps'}/" in lines[0] and "No space left on device" in lines[0]
        assert os.listdir(full) == []


def test_numpys_short_write_on_a_full_disk_is_named(tmp_path, monkeypatch):
    """numpy reports a short write as "N requested and M written", with no errno."""
    import shutil

    from tofnet.errors import DataError
    from tofnet.io import files
    from tofnet.io.npy import write_npy

    def short(*args, **kwargs):
        raise OSError("43200 requested and 34784 written")
    monkeypatch.setattr(np, "save", short)
    monkeypatch.setattr(files.shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 10**9, 4096))
    with pytest.raises(DataError, match=r"a.npy: cannot write: No space left on device \(43200 requested"):
        write_npy(tmp_path / "a.npy", np.zeros(3))
    assert os.listdir(tmp_path) == []
