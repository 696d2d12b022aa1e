"""open_recording: detection by content, chunks with bounded memory, the CLI's input options."""

import tracemalloc

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.events import EVENT_DTYPE, make_events
from tofnet.io import detect_format, read_recording
from tofnet.io.source import EventSource
from optional import optional


def test_content_decides_over_the_name(tmp_path):
    events = make_events([1, 2], [3, 4], [5, 6], [1, 0])
    np.save(tmp_path / "a.npy", events)
    (tmp_path / "a.npy").rename(tmp_path / "events.dat")
    assert detect_format(tmp_path / "events.dat") == "npy"
    assert np.array_equal(read_recording(tmp_path / "events.dat").events, events)
    (tmp_path / "x.bag").write_bytes(b"#!AER-DAT2.0\r\n")
    with pytest.raises(DataError, match="AEDAT 2.0 is not supported, only AEDAT4"):
        detect_format(tmp_path / "x.bag")
    (tmp_path / "y.bin").write_bytes(b"\x00\x01\x02garbage")
    with pytest.raises(DataError, match="y.bin: unknown recording format"):
        detect_format(tmp_path / "y.bin")
    (tmp_path / "z.h5").write_bytes(b"not hdf5 at all")
    with pytest.raises(DataError, match="'.h5' names HDF5 but the content does not start like one"):
        detect_format(tmp_path / "z.h5")
    # Prophesee: DAT's header says its version, RAW's its evt; the suffix only breaks a tie
    (tmp_path / "dat.raw").write_bytes(b"% Version 2\n% Width 640\n% Height 480\n\x0c\x08")
    (tmp_path / "evt.dat").write_bytes(b"% evt 3.0\n% end\n")
    (tmp_path / "bare.raw").write_bytes(b"% date 2020\n% end\n")
    assert [detect_format(tmp_path / n) for n in ("dat.raw", "evt.dat", "bare.raw")] == ["dat", "evt", "evt"]


class _Synthetic(EventSource):
    """A long recording generated packet by packet (nothing held but the current packet)."""

    format = "synthetic"

    def __init__(self, n_packets, packet, back_at=None):
        super().__init__("synthetic")
        self.n_packets, self.packet, self.back_at = n_packets, packet, back_at

    def _packets(self, size_hint):
        for k in range(self.n_packets):
            events = np.zeros(self.packet, dtype=EVENT_DTYPE)
            events["t"] = k * self.packet + np.arange(self.packet)
            if self.back_at == k:
                events["t"][0] -= 5
            yield events


def test_chunks_hold_bounded_memory():
    list(_Synthetic(n_packets=2, packet=10).chunks(5))  # compile (or load) the copy kernel first
    source = _Synthetic(n_packets=400, packet=10_000)  # 4 M events, 52 MB if held at once
    tracemalloc.start()
    total = 0
    for chunk in source.chunks(100_000):
        total += len(chunk)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert total == 4_000_000
    assert peak < 4 * 100_000 * EVENT_DTYPE.itemsize  # a few chunks' worth, not the recording


def test_time_going_back_across_a_chunk_boundary_is_caught():
    with pytest.raises(DataError, match="event 30001: time goes back"):
        for _ in _Synthetic(n_packets=5, packet=10_000, back_at=3).chunks(30_000):
            pass


def test_cli_run_with_columns_and_missing_extra(tmp_path, capsys, monkeypatch):
    import sys

    from tofnet.io.calibration import write_calibration
    from tofnet.io.recording import Intrinsics
    from tofnet.testing import moving_edge

    events = moving_edge((240, 180), -50.0, "u")[:20_000]
    rows = np.column_stack([events["x"], events["y"], events["t"] * 1e-6, events["p"]])
    np.save(tmp_path / "rows.npy", rows)
    write_calibration(tmp_path / "calib.txt", Intrinsics(200.0, 200.0, 119.5, 89.5))
    args = ["run", str(tmp_path / "rows.npy"), "--velocity", "0.5,0,0", "--out", str(tmp_path / "d.npz"), "--quiet"]
    assert main(args + ["--columns", "x,y,t,p"]) == 0
    assert f"events in      {len(events):>12,}" in capsys.readouterr().out
    assert main(args + ["--force"]) == 2  # the first run wrote d.npz
    assert "--columns" in capsys.readouterr().err
    optional("h5py")
    from tofnet.io.hdf5 import write_hdf5
    from tofnet.io.recording import Recording
    write_hdf5(tmp_path / "e.h5", [events], Recording(events=events))
    monkeypatch.setitem(sys.modules, "h5py", None)
    assert main(["info", str(tmp_path / "e.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install \"tofnet[hdf5]\"" in err and "e.h5" in err


def test_topic_option_needs_role_and_name(capsys):
    assert main(["info", "x.bag", "--topic", "events"]) == 2
    assert "expected ROLE=NAME" in capsys.readouterr().err
