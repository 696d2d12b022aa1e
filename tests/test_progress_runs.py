"""Progress on long runs: after the events are processed (a streamed window of one chunk on a slow backend
reports as it goes), and with monitors (a session model by model); the results do not change."""

import numpy as np
import pytest

import tofnet.pacing
from tofnet.api import constant_velocity, default_network, run, run_source
from tofnet.io import read_recording
from tofnet.io.recording import Intrinsics
from tofnet.io.source import open_recording
from tofnet.io.ecd import write_ecd
from tofnet.testing import moving_pattern

SENSOR = (24, 16)


@pytest.fixture
def recording_folder(tmp_path):
    events = moving_pattern(SENSOR, (300, -150), 1_000_000, seed=1)  # about 27,000 events: pieces of 4,096
    write_ecd(tmp_path / "rec", events, intrinsics=Intrinsics(200, 200, 12, 8), sensor_size=SENSOR)
    return tmp_path / "rec"


def _network():
    network = default_network(sensor_size=SENSOR)
    constant_velocity(network, "0.5,0,0")
    return network


def test_a_single_chunk_reports_progress_as_it_is_processed(recording_folder, monkeypatch):
    calls, fed = [], []
    with open_recording(recording_folder) as source:
        plain, _ = run_source(source, _network(), backend="reference")
    monkeypatch.setattr(tofnet.pacing, "PIECE_SECONDS", 1e-4)  # this small run as slowly as a long one
    with open_recording(recording_folder) as source:
        total = source.n_events
        assert total < 1 << 17  # one chunk
        original = type(source).chunks

        def counted(self, *args, **kwargs):  # the events read so far: progress counts none beyond them
            for chunk in original(self, *args, **kwargs):
                fed.append(len(chunk))
                yield chunk
        monkeypatch.setattr(type(source), "chunks", counted)
        paced, _ = run_source(source, _network(), backend="reference", progress=lambda d, t: calls.append((d, t)))
    assert len(calls) > 3 and calls[-1][0] == total == sum(fed)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)
    for name in plain.outputs:
        np.testing.assert_array_equal(paced.outputs[name], plain.outputs[name])


def test_a_run_with_monitors_reports_progress(recording_folder, monkeypatch):
    recording = read_recording(recording_folder)
    monitor = "time_of_travel.counter@5,5"
    plain, _ = run(recording, _network(), monitors=[monitor])
    monkeypatch.setattr(tofnet.pacing, "PIECE_SECONDS", 1e-4)
    calls = []
    paced, _ = run(recording, _network(), monitors=[monitor], progress=lambda d, t: calls.append((d, t)))
    assert len(calls) > 3 and calls[-1] == (len(recording.events), len(recording.events))
    for name in plain.outputs:
        np.testing.assert_array_equal(paced.outputs[name], plain.outputs[name])
    (a,), (b,) = plain.extra["monitors"], paced.extra["monitors"]
    for key, value in a.arrays().items():
        np.testing.assert_array_equal(b.arrays()[key], value)


def test_a_streamed_run_with_progress_chooses_its_bands_on_its_chunks_not_its_pieces(recording_folder, monkeypatch):
    """Pieces start small, and a stream keeps one band on a small first packet (a live stream's latency): a run's
    bands are chosen on its chunks, as without progress, and give the estimates of one worker."""
    import tofnet.backends.bands
    monkeypatch.setattr(tofnet.pacing, "PIECE_SECONDS", 1e-4)
    monkeypatch.setattr(tofnet.backends.bands, "FUSED_BANDS_FROM", 10_000)  # the chunk (~27,000) above, pieces below
    runs = {}
    for workers, progress in ((1, None), (2, None), (2, lambda d, t: None)):
        with open_recording(recording_folder) as source:
            runs[workers, progress is None], _ = run_source(source, _network(), backend="fixed",
                                                            backend_options={"workers": workers}, progress=progress)
    quiet, paced = runs[2, True].summary()["workers"], runs[2, False].summary()["workers"]
    assert paced == quiet and paced["bands"] == 2 and "one_band" not in paced, paced
    for name in runs[1, True].outputs:
        np.testing.assert_array_equal(runs[2, False].outputs[name], runs[1, True].outputs[name])
