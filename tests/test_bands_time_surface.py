"""The time-surface estimator in bands of rows: byte-identical to one worker, alone and beside the paper's network."""

import numpy as np
import pytest

from tofnet import Session
from tofnet.backends.event_driven import FixedBackend, FloatBackend
from tofnet.backends.registry import get_backend
from tofnet.conformance.workers import first_difference
from tofnet.core.network import Network
from tofnet.io.recording import Recording
from tofnet.kernels import time_surface as ts
from tofnet.networks import depth_network, improved_network
from tofnet.processes import TimeSurfaceProcess
from tofnet.testing import TEST_INTRINSICS, merge_events, moving_pattern, noise_events

from test_bands import SENSOR, VELOCITY, edge_events, hand_over, with_bands  # noqa: F401  (a fixture)

#: Bands of one row (narrower than the fit's radius of 3), of two and of the rest.
NARROW = [(0, 1), (1, 2), (2, 3), (3, 9), (9, 10), (10, 16)]


def surface_network():
    return improved_network(SENSOR, time_surface={"t0": 0}, velocity=VELOCITY)


def both_networks():
    """The paper's network and the time surface side by side on one velocity process."""
    paper = depth_network(SENSOR, input={"refractory": "1ms", "t0": 0}, velocity=VELOCITY)
    surface = TimeSurfaceProcess(name="time_surface", sensor_size=SENSOR, t0=0)
    paper.process("velocity").a_t.connect(surface.a_t)
    return Network([*paper.processes, surface], name="both")


def texture(rows=None, seed=1):
    events = merge_events(moving_pattern(SENSOR, (300, -150), 120_000, seed=seed, sample_us=50),
                          noise_events(SENSOR, 20, 120_000, seed=seed + 1))
    if rows is not None:
        events = events[np.isin(events["y"], rows)]
    return Recording(events, intrinsics=TEST_INTRINSICS)


@pytest.mark.parametrize("cls", [FixedBackend, FloatBackend])
@pytest.mark.parametrize("bands", [NARROW, [(0, 5), (5, 6), (6, 16)], [(0, 15), (15, 16)]])
@pytest.mark.parametrize("network", [surface_network, both_networks])
def test_bands_narrower_than_the_fit_and_events_on_band_edges_change_nothing(cls, bands, network):
    edges = sorted({b for band in bands for b in band if 0 < b < SENSOR[1]} | {b - 1 for band in bands for b in band
                                                                               if 0 < b < SENSOR[1]})
    recording = Recording(merge_events(edge_events(SENSOR, edges), texture().events), intrinsics=TEST_INTRINSICS)
    one = cls().run(network(), recording)
    banded = with_bands(cls, bands).run(network(), recording)
    counts = one.counts["time_surface"]
    assert counts["emitted"] > 50 and counts["out_of_bounds"] == 2 and counts["burst"] > 100
    assert first_difference(banded, one) == ""
    assert "time_surface" in banded.extra["banded"] and "velocity" in banded.extra["whole"]


@pytest.mark.parametrize("packet", [1, 97, 4096])
def test_bands_without_events_and_packets_of_any_size(hand_over, packet):
    recording = texture(rows=range(6))  # only the top rows fire: the bands below have no events
    one = FixedBackend().run(surface_network(), recording)
    banded = with_bands(FixedBackend, [(0, 4), (4, 8), (8, 12), (12, 16)], packet_events=packet)
    assert first_difference(banded.run(surface_network(), recording), one) == ""
    assert one.counts["time_surface"]["emitted"] > 20


def test_a_stream_with_workers_returns_the_run_in_any_packets():
    recording = texture()
    one = FixedBackend().run(both_networks(), recording)
    stream = get_backend("fixed", workers=3).open_stream(both_networks(), recording=recording)
    events, parts = recording.events, []
    for lo in range(0, len(events), 311):
        parts.append(stream.feed_all(events[lo:lo + 311]))
    result = stream.close()
    parts.append(result.outputs)
    for name in ("time_surface.depth", "time_surface.quality", "depth.depth"):
        got = np.concatenate([p[name] for p in parts if name in p])
        assert got.tobytes() == one.outputs[name].tobytes(), name
    assert result.counts == one.counts and len(result.extra["bands"]) == 3


def test_sessions_gather_and_scatter_the_surface_across_bands():
    recording = texture()
    with Session(surface_network(), recording, backend="fixed") as one, \
            Session(surface_network(), recording, backend="fixed", backend_options={"workers": 3}) as three:
        for steps in (17, 40):
            one.run(steps=steps)
            three.run(steps=steps)
            for name in ("time_surface.last_first_event", "time_surface.hold"):
                assert np.array_equal(one.get(name), three.get(name)), name
        surface = one.get("time_surface.last_first_event")
        assert (surface > 0).sum() > 50
        surface[:, 4:12, :] = ts.NEVER  # forget the edges of rows across every band edge, halos included
        for session in (one, three):
            session.set("time_surface.last_first_event", surface)
            session.set("time_surface.hold", 0)
        assert np.array_equal(three.get("time_surface.last_first_event"), surface)
        a, b = one.finish(), three.finish()
    assert first_difference(b, a) == ""


def test_the_kernels_bands_run_in_threads_release_the_gil():
    # Bands are threads: a kernel that holds the GIL runs them one at a time (the time surface's did).
    from tofnet.kernels import time_of_travel, time_surface
    for kernel in (time_surface.process, time_of_travel.process_events):
        assert kernel.targetoptions.get("nogil") is True, kernel.__name__


def test_a_band_without_events_while_the_velocity_changes_keeps_the_clock(tmp_path):
    # A band is fed its rows' events and each step's first event: its travel ring and motion epochs
    # must move at the steps where one whole kernel's move, also while its own rows are silent.
    samples = tmp_path / "velocity.txt"
    samples.write_text("".join(f"{k * 0.01:.3f} {-0.5 + 0.3 * (k % 3)} {0.2 - 0.1 * (k % 2)} {0.05 * (k % 4)}\n"
                               for k in range(14)))
    velocity = {"source": "samples", "samples": str(samples), "per": "pixel"}
    events = texture().events
    quiet = (events["y"] >= 8) & (((events["t"] > 15_000) & (events["t"] < 65_000)) | (events["t"] > 95_000))
    recording = Recording(events[~quiet], intrinsics=TEST_INTRINSICS)
    network = improved_network(SENSOR, time_surface={"t0": 0}, velocity=velocity)
    one = FixedBackend().run(network, recording)
    banded = with_bands(FixedBackend, [(0, 8), (8, 16)]).run(network, recording)
    assert one.counts["time_surface"]["emitted"] > 20
    assert first_difference(banded, one) == ""
