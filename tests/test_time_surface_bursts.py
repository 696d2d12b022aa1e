"""Burst-index surfaces (``burst_surfaces`` K > 1): a burst's later events fitted on their own surfaces."""

import hashlib

import numpy as np
import pytest

from tofnet import Session
from tofnet.backends.event_driven import FixedBackend
from tofnet.conformance.workers import first_difference
from tofnet.errors import BackendError
from tofnet.events import make_events
from tofnet.io.recording import Recording
from tofnet.kernels import time_surface as ts
from tofnet.networks import improved_network
from tofnet.testing import TEST_INTRINSICS, merge_events, moving_pattern, noise_events

from test_bands import SENSOR as BAND_SENSOR, VELOCITY, with_bands  # noqa: F401  (a fixture)
from test_time_surface import F, noisy_stream, run

DEPTH = 1.5


def burst_edge(seed=0, bursts=4, gap_us=1500, jitter_us=40, speed=100.0, sensor=(32, 24)):
    """A straight edge along +u at ``speed`` px/s; each pixel fires ``bursts`` events ``gap_us`` apart, each
    with its own jitter (``jitter_us`` rms): a burst's k-th events fire in step along the motion, as the first."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:sensor[1], 0:sensor[0]]
    t = 1000 + np.round(xs / speed * 1e6).astype(np.int64)
    times = np.concatenate([(t + k * gap_us + np.round(rng.normal(0, jitter_us, t.shape))).ravel()
                            for k in range(bursts)])
    x, y = np.tile(xs.ravel(), bursts), np.tile(ys.ravel(), bursts)
    order = np.argsort(times, kind="stable")
    events = make_events(times[order], x[order], y[order], np.ones(len(times), np.uint8))
    return events, (-speed * DEPTH / F, 0.0, 0.0)


def test_later_burst_events_are_fitted_on_their_own_surfaces():
    events, velocity = burst_edge()
    depth1, quality1, one = run(events, velocity, burst_surfaces=1)
    depth3, quality3, three = run(events, velocity, burst_surfaces=3, burst_fit="all")
    assert (quality1["burst"] == 0).all() and one.counts["burst"] == 3 * len(events) // 4
    k = quality3["burst"]
    assert set(np.unique(k)) == {0, 1, 2} and np.count_nonzero(k > 0) > len(depth1)
    # the first events' estimates are those of one surface (their fits read surface 0 only)
    first = quality3[k == 0]
    assert np.array_equal(first["index"], quality1["index"]) and np.array_equal(depth3[k == 0], depth1)
    # a later event's estimate is its own fit, not its edge's first event's depth: at the same pixel the
    # depths differ (each surface has its own jitter), and each is close to the truth
    by_pixel = {(int(d["x"]), int(d["y"])): float(d["z"]) for d in depth1}
    later = depth3[k > 0]
    same = [by_pixel.get((int(d["x"]), int(d["y"]))) == float(d["z"]) for d in later]
    assert not any(same)
    assert abs(np.median(later["z"]) / DEPTH - 1) < 0.03 and abs(np.median(depth1["z"]) / DEPTH - 1) < 0.03
    assert not np.array_equal(quality3["rms_px"][k == 1][:10], quality3["rms_px"][k == 0][:10])
    # events beyond the K surfaces stay a burst's; every event ends in one count
    counts = three.counts
    assert counts["burst"] == len(events) // 4 and sum(counts.values()) == len(events)
    assert three.first_events == 3 * len(events) // 4


def test_a_later_event_where_its_pixel_already_emitted_in_the_step_is_not_fitted():
    """Its estimate would end ``same_step`` whatever its fit (a later event's fit sets no hold): it is counted
    so at once, with no points; later events in steps of their own are fitted as before."""
    events, velocity = burst_edge(gap_us=300)  # a burst's events 0.3 ms apart: often in one 1 ms step
    depth, quality, estimator = run(events, velocity, burst_surfaces=3, burst_fit="all", record_rejected=True)
    emitted = set()
    repeats = fitted = 0
    for d, q in zip(depth, quality):
        key = (int(d["x"]), int(d["y"]), int(d["step"]))
        if q["burst"] > 0 and key in emitted:
            assert q["reason"] == ts.SAME_STEP and q["points"] == 0
            repeats += 1
        elif q["burst"] > 0:
            assert q["reason"] != ts.SAME_STEP or q["points"] > 0
            fitted += q["points"] > 0
        if q["reason"] == ts.EMITTED:
            emitted.add(key)
    assert repeats > 100 and fitted > 100
    assert estimator.counts["same_step"] == repeats + np.count_nonzero((quality["reason"] == ts.SAME_STEP)
                                                                       & (quality["points"] > 0))


@pytest.mark.parametrize("which", ["fitted", "emitted"])
def test_fitted_or_emitted_only_fits_fewer_later_events(which):
    events, velocity = burst_edge()
    _, q_all, _ = run(events, velocity, burst_surfaces=3, burst_fit="all", record_rejected=True)
    _, q_some, _ = run(events, velocity, burst_surfaces=3, burst_fit=which, record_rejected=True)
    some, every = np.count_nonzero(q_some["burst"] > 0), np.count_nonzero(q_all["burst"] > 0)
    # one edge: every first event passed the hold (no fit has set one yet), not every one was emitted
    assert 0 < some == every if which == "fitted" else 0 < some < every
    assert np.array_equal(q_some[q_some["burst"] == 0], q_all[q_all["burst"] == 0])  # the first events' the same


def test_one_surface_is_the_estimator_before_burst_surfaces():
    """``burst_surfaces`` 1 gives the bytes of the estimator before burst surfaces (digests taken at 3e6206d)."""
    events, velocity = noisy_stream()
    depth, quality, estimator = run(events, velocity, burst_surfaces=1, record_rejected=True)
    fields = [name for name in quality.dtype.names if name != "burst"]
    digest = hashlib.sha256(depth.tobytes() + b"".join(np.ascontiguousarray(quality[n]).tobytes() for n in fields))
    assert (len(depth), estimator.counts["emitted"]) == (EXPECTED_ROWS, EXPECTED_EMITTED)
    assert digest.hexdigest()[:16] == EXPECTED_DIGEST


EXPECTED_ROWS, EXPECTED_EMITTED, EXPECTED_DIGEST = 1885, 1317, "fa2648745f4735bb"


def test_burst_surfaces_output_does_not_depend_on_packets():
    events, velocity = noisy_stream()
    whole = run(events, velocity, burst_surfaces=3)
    cuts = sorted({0, 1, 777, 778, len(events) // 3, len(events) // 2, len(events)})
    split = run(events, velocity, packets=cuts, burst_surfaces=3)
    assert whole[0].tobytes() == split[0].tobytes() and whole[1].tobytes() == split[1].tobytes()
    assert (whole[1]["burst"] > 0).any()


def test_a_bad_burst_setting_is_refused():
    with pytest.raises(BackendError, match="burst_fit.*burst_surfaces"):
        run(*burst_edge(), burst_surfaces=0, burst_fit="some")


def band_network(burst_fit="all"):
    return improved_network(BAND_SENSOR, time_surface={"t0": 0, "burst_surfaces": 3, "burst_fit": burst_fit},
                            velocity=VELOCITY)


def band_recording(seed=1):
    events = merge_events(moving_pattern(BAND_SENSOR, (300, -150), 120_000, seed=seed, sample_us=50),
                          noise_events(BAND_SENSOR, 20, 120_000, seed=seed + 1))
    return Recording(events, intrinsics=TEST_INTRINSICS)


@pytest.mark.parametrize("burst_fit", ["all", "emitted"])
@pytest.mark.parametrize("bands", [[(0, 8), (8, 16)], [(0, 1), (1, 2), (2, 9), (9, 16)]])
def test_bands_equal_one_band_with_burst_surfaces(bands, burst_fit):
    recording = band_recording()
    one = FixedBackend().run(band_network(burst_fit), recording)
    banded = with_bands(FixedBackend, bands).run(band_network(burst_fit), recording)
    assert first_difference(banded, one) == ""
    single = FixedBackend().run(improved_network(BAND_SENSOR, time_surface={"t0": 0, "burst_surfaces": 1},
                                                 velocity=VELOCITY), recording)
    assert one.counts["time_surface"]["emitted"] > single.counts["time_surface"]["emitted"]


def test_last_first_event_is_the_first_events_surface_and_setting_it_forgets_the_later_ones():
    recording = band_recording()
    untouched = FixedBackend().run(band_network(), recording)
    results = []
    for forget in (False, True):
        with Session(band_network(), recording, backend="fixed") as session:
            session.run(steps=60)
            surface = session.get("time_surface.last_first_event")
            assert surface.shape == (2, BAND_SENSOR[1], BAND_SENSOR[0]) and (surface > ts.NEVER).sum() > 20
            session.set("time_surface.last_first_event", ts.NEVER if forget else surface)
            if forget:
                assert (session.get("time_surface.last_first_event") == ts.NEVER).all()
            results.append(session.finish())
    kept, forgot = (r.counts["time_surface"] for r in results)
    assert kept == untouched.counts["time_surface"]  # setting what it holds changes nothing
    assert results[0].depth.tobytes() == untouched.depth.tobytes()
    assert forgot["nothing_behind"] > kept["nothing_behind"] and forgot["emitted"] < kept["emitted"]
