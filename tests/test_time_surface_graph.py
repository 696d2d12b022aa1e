"""The time-surface process in the open graph: equal to the estimator, on every backend, in sessions and streams."""

import json

import numpy as np
import pytest

from tofnet import Session
from tofnet.api import default_network, load_network, run
from tofnet.backends.multiproc import MultiprocBackend
from tofnet.backends.registry import available_backends, get_backend
from tofnet.compiler import compile_network
from tofnet.core.network import Network
from tofnet.errors import BackendError, NetworkError
from tofnet.io.recording import Intrinsics, Recording
from tofnet.kernels import time_surface as ts
from tofnet.kernels.time_surface_estimator import TimeSurfaceConfig, TimeSurfaceEstimator, constant_velocity
from tofnet.networks import improved_network
from tofnet.processes import TimeSurfaceProcess, VelocityProcess
from tofnet.testing import (TEST_INTRINSICS, LinearVelocity, camera_flow, flowing_pattern, merge_events,
                            moving_pattern, noise_events)

SENSOR = (28, 20)
FLOW = (250.0, -120.0)  # px/s
VELOCITY = (-FLOW[0] / TEST_INTRINSICS.fx, -FLOW[1] / TEST_INTRINSICS.fy, 0.0)  # a texture at 1 m
K = (TEST_INTRINSICS.fx, TEST_INTRINSICS.fy, TEST_INTRINSICS.cx, TEST_INTRINSICS.cy)


def jittered(events, seed, jitter_us=600):
    """Events with times moved by up to ``jitter_us`` (re-sorted): the fits then reject and drop."""
    rng = np.random.default_rng(seed)
    events = events.copy()
    events["t"] += rng.integers(0, jitter_us, len(events))
    return events[np.argsort(events["t"], kind="stable")]


EVENTS = jittered(merge_events(moving_pattern(SENSOR, FLOW, 220_000, seed=3, sample_us=50, start_us=1_000),
                               noise_events(SENSOR, 10, 220_000, seed=4)), 5)
RECORDING = Recording(EVENTS, intrinsics=TEST_INTRINSICS, sensor_size=SENSOR)


def network(velocity=None, **surface):
    return improved_network(SENSOR, time_surface={"t0": 0, **surface},
                            velocity=velocity or {"source": "constant", "velocity": list(VELOCITY)})


def standalone(events, rows, **changes):
    """The estimator alone, fed the whole stream; estimates in the canonical order (step, y, x)."""
    config = TimeSurfaceConfig(SENSOR, K, **changes)
    estimator = TimeSurfaceEstimator(config, t0_us=0)
    depth, quality = estimator.feed(events, rows)
    order = np.lexsort((depth["x"], depth["y"], depth["step"]))
    return depth[order], quality[order], estimator


@pytest.fixture(scope="module")
def workers():
    with MultiprocBackend(workers=2).session() as session:
        yield session


@pytest.mark.parametrize("backend", ["reference", "float", "fixed"])
def test_every_backend_gives_the_estimators_records_and_counts(backend):
    depth, quality, estimator = standalone(EVENTS, constant_velocity(VELOCITY))
    result, _ = run(RECORDING, network(), backend=backend)
    assert len(depth) > 500
    assert result.depth.tobytes() == depth.tobytes()
    fit = result.outputs["time_surface.quality"]
    assert np.array_equal(fit["t_event"], quality["t_event"]) and np.array_equal(fit["gx"], quality["gx"])
    assert np.array_equal(fit["step"], depth["step"]) and np.array_equal(fit["x"], depth["x"])
    counts = result.counts["time_surface"]
    assert {k: counts[k] for k in ts.COUNT_NAMES} == estimator.counts
    drops = counts["out_of_bounds"] + counts["before_t0"] + counts["burst"]
    assert counts["events_in"] == counts["accepted"] + drops == len(EVENTS) == result.events_in
    assert result.latency == {"time_surface.depth": 1, "time_surface.quality": 1}
    assert result.steps == int(EVENTS["t"][-1]) // 1000 + 2  # the last event's step + its latency + 1


def test_estimates_are_stamped_one_step_after_their_event():
    result, _ = run(RECORDING, network(), backend="fixed")
    fit = result.outputs["time_surface.quality"]
    np.testing.assert_array_equal(result.depth["step"], fit["t_event"] // 1000 + 1)
    np.testing.assert_array_equal(result.depth["t"], (result.depth["step"] + 1) * 1000)


def test_velocity_comes_from_the_a_t_records_and_any_update_rate():
    """The held update of each step, as the depth neurons take it: a ramp sent every 3 steps."""
    ramp = LinearVelocity(VELOCITY, (1.5 * VELOCITY[0], 1.5 * VELOCITY[1], 0.1), 0.2)  # m/s over 0.2 s
    recording = Recording(EVENTS, intrinsics=TEST_INTRINSICS, sensor_size=SENSOR, trajectory=ramp)
    result, _ = run(recording, network({"source": "groundtruth", "update_every": 3}), backend="fixed")
    from tofnet.models.binding import velocity_table

    def rows(first, count):  # update j is sent in step 3j: the velocity at its start
        return velocity_table(ramp, 0, 1000, 3, count, first), first

    depth, _, _ = standalone(EVENTS, rows, update_every=3)
    assert len(depth) > 300 and result.depth.tobytes() == depth.tobytes()
    # a constant velocity process ignores the recording's motion: the records decide, not the recording
    constant, _ = run(recording, network(), backend="fixed")
    assert constant.depth.tobytes() == standalone(EVENTS, constant_velocity(VELOCITY))[0].tobytes()


def test_a_t_per_patch_follows_the_velocity_process():
    result, _ = run(RECORDING, network({"source": "constant", "velocity": [-0.4, 0.3, 0.6], "per": "patch",
                                        "patch_size": 7}), backend="fixed")
    depth, _, _ = standalone(EVENTS, constant_velocity((-0.4, 0.3, 0.6)), per_pixel=False, patch_size=7)
    assert len(depth) > 100 and result.depth.tobytes() == depth.tobytes()


@pytest.mark.parametrize("coordinates", ["time", "travel"])
def test_b_w_makes_it_eq_7_with_the_angular_velocity_records(coordinates):
    intrinsics = Intrinsics(200.0, 200.0, 13.5, 9.5)
    velocity, omega = (-0.3, 0.1, 0.05), (0.05, -0.2, 0.1)
    flow = camera_flow(intrinsics, 1.0, velocity, omega)
    events = jittered(flowing_pattern(SENSOR, flow, 200_000, seed=6), 7, 300)
    recording = Recording(events, intrinsics=intrinsics, sensor_size=SENSOR)
    net = improved_network(SENSOR, time_surface={"t0": 0, "coordinates": coordinates},
                           velocity={"source": "constant", "velocity": list(velocity)},
                           rotation={"source": "constant", "omega": list(omega), "update_every": 2})
    result, _ = run(recording, net, backend="fixed")
    k = (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy)
    config = TimeSurfaceConfig(SENSOR, k, coordinates=coordinates)
    estimator = TimeSurfaceEstimator(config, t0_us=0)
    depth, _ = estimator.feed(events, constant_velocity(velocity, omega))
    depth = depth[np.lexsort((depth["x"], depth["y"], depth["step"]))]
    # travel: the first 100 ms (the window) are fitted net of the rotation, which leaves less spread along the motion
    assert len(depth) > (200 if coordinates == "time" else 150) and result.depth.tobytes() == depth.tobytes()
    plain, _ = run(recording, improved_network(SENSOR, time_surface={"t0": 0, "coordinates": coordinates},
                                               velocity={"source": "constant", "velocity": list(velocity)}))
    # the texture is at 1 m; eq. 8 reads the turn as depth
    assert np.median(np.abs(result.depth["z"] - 1.0)) < 0.5 * np.median(np.abs(plain.depth["z"] - 1.0))


@pytest.mark.parametrize("name", available_backends())
def test_chunks_of_1_7_and_1000_steps_equal_one_run(name, workers):
    compiled = compile_network(network())
    whole = get_backend(name, **({"workers": 2} if name == "multiproc" else {})).run(compiled, RECORDING)
    assert len(whole.depth) > 500
    for chunk in (1, 7, 1000):
        with Session(compiled, RECORDING, backend=workers if name == "multiproc" else name) as s:
            while s.step < 130:
                s.run(steps=chunk)
            ran = s.step  # past the run's end: those steps ran too
            result = s.finish()
        for key, records in whole.outputs.items():
            assert result.outputs[key].tobytes() == records.tobytes(), (chunk, key)
        assert result.counts == whole.counts and result.steps == max(whole.steps, ran)


def test_a_stream_fed_packets_split_anywhere_equals_one_run():
    whole, _ = run(RECORDING, network(), backend="fixed")
    stream = get_backend("fixed").open_stream(network(), recording=RECORDING)
    cuts = np.unique(np.r_[0, np.random.default_rng(8).integers(0, len(EVENTS), 30), len(EVENTS)])
    parts = [stream.feed(EVENTS[lo:hi]) for lo, hi in zip(cuts[:-1], cuts[1:])]
    closed = stream.close()
    got = np.concatenate(parts + [closed.outputs["time_surface.depth"]])
    assert got.tobytes() == whole.depth.tobytes() and closed.counts == whole.counts


def test_the_surface_is_a_variable_read_and_set_between_runs():
    with Session(network(), RECORDING, backend="fixed") as s:
        s.run(steps=60)
        surface = s.get("time_surface.last_first_event")
        hold = s.get("time_surface.hold")
        # at the start of step 60 the events answered before it (input steps <= 58) have run
        _, _, estimator = standalone(EVENTS[EVENTS["t"] < 59_000], constant_velocity(VELOCITY))
        width, height = SENSOR
        r = estimator.config.radius
        expected = estimator._surface.reshape(-1, 2, height + 2 * r, width + 2 * r)[0, :, r:-r, r:-r]  # surface 0
        assert surface.shape == (2, height, width) and np.array_equal(surface, expected)
        assert np.array_equal(hold, np.moveaxis(estimator._hold.reshape(height, width, 2), 2, 0))
        assert (surface > 0).sum() > 100 and (hold > 0).sum() > 50
        s.set("time_surface.last_first_event", ts.NEVER)  # forget every edge: the next fits start afresh
        assert (s.get("time_surface.last_first_event") == ts.NEVER).all()
        s.set("time_surface.hold", 0)
        result = s.finish()
    untouched, _ = run(RECORDING, network(), backend="fixed")
    forgot, kept = result.counts["time_surface"], untouched.counts["time_surface"]
    # with no edge behind them the next first events are not fitted, and fewer estimates come out
    assert forgot["nothing_behind"] > kept["nothing_behind"] + 25 and forgot["emitted"] < kept["emitted"] - 30


def test_multiproc_runs_it_in_the_parent_and_equals_fixed(workers):
    fixed, _ = run(RECORDING, network(), backend="fixed")
    multi = workers.run(RECORDING, compiled=compile_network(network()))
    assert multi.depth.tobytes() == fixed.depth.tobytes() and multi.counts == fixed.counts


def test_the_improved_network_and_the_estimator_option():
    net = default_network(RECORDING, estimator="improved")
    assert [type(p).__name__ for p in net.processes] == ["TimeSurfaceProcess", "VelocityProcess"]
    assert net.process("velocity").per == "pixel" and net.sensor_size == SENSOR
    with pytest.raises(NetworkError, match="estimator"):
        default_network(RECORDING, estimator="best")
    from tofnet.testing import turning_trajectory
    turning = Recording(EVENTS, intrinsics=TEST_INTRINSICS, sensor_size=SENSOR,
                        trajectory=turning_trajectory((-0.3, 0.0, 0.0), (0.0, 0.2, 0.0), 0.3))
    compensated = default_network(turning, estimator="improved")  # as the paper's default network does
    assert [t.process.name for t in compensated.process("angular_velocity").b_w.targets] == ["time_surface"]
    assert "angular_velocity" not in [p.name for p in default_network(turning, estimator="improved",
                                                                      rotation=False).processes]
    with pytest.raises(NetworkError, match="spec names its own"):
        load_network("examples/improved.yaml", estimator="improved")
    spec_net, _, _, _ = load_network("examples/improved.yaml")
    defaults = TimeSurfaceProcess(name="d")
    assert spec_net.process("time_surface").values == {**defaults.values, "sensor_size": (240, 180)}
    import yaml  # the file writes out every parameter but t0 (the first event's time), as its header says
    written = set(yaml.safe_load(open("examples/improved.yaml"))["processes"]["time_surface"]) - {"type"}
    assert written == {param.name for param in TimeSurfaceProcess.params} - {"t0"}


def test_a_bad_parameter_is_one_line_naming_it():
    with pytest.raises(NetworkError, match="time_surface.model"):
        TimeSurfaceProcess(name="time_surface", model="cubic")
    with pytest.raises(NetworkError, match="min_depth"):
        TimeSurfaceProcess(name="time_surface", min_depth=3, max_depth=2)
    with pytest.raises(NetworkError, match="window"):
        TimeSurfaceProcess(name="time_surface", window=0, window_depth=0)
    with pytest.raises(NetworkError, match=r"time_surface.radius: coordinates: travel, behind_depth, window_px need "
                                           r"radius >= 2 .*got 1$"):
        TimeSurfaceProcess(name="time_surface", radius=1)  # when declared, not at the first event
    assert TimeSurfaceProcess(name="time_surface", radius=1, coordinates="time", behind_depth=0,
                              window_px=0).values["radius"] == 1
    vel = VelocityProcess(name="velocity", source="constant", velocity=[0.1, 0, 0])
    surface = TimeSurfaceProcess(name="time_surface", sensor_size=SENSOR, t0=0)
    vel.a_t.connect(surface.a_t)
    stream = get_backend("fixed").open_stream(Network([surface, vel]), recording=RECORDING)
    stream.feed(EVENTS[100:200])
    with pytest.raises(BackendError, match="not sorted by time"):
        stream.feed(EVENTS[:50])


def test_run_eval_and_compile_from_the_command_line(tmp_path, capsys):
    from tofnet.cli import main
    from tofnet.io import read_depth
    from tofnet.io.ecd import write_ecd

    times = np.linspace(0, 0.25, 26)
    positions = np.outer(times, VELOCITY)
    write_ecd(tmp_path / "rec", EVENTS, intrinsics=TEST_INTRINSICS, times=times, positions=positions,
              quaternions=np.tile([0.0, 0.0, 0.0, 1.0], (len(times), 1)), sensor_size=SENSOR,
              gt_depth=np.ones(len(EVENTS)))  # the texture lies at 1 m
    out = tmp_path / "depth.npz"
    assert main(["run", str(tmp_path / "rec"), "--estimator", "improved", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    depth, meta = read_depth(out)
    assert meta["latency_steps"] == 1 and len(depth) > 900
    assert abs(np.median(depth["z"]) - 1.0) < 0.03  # the texture is at 1 m
    for line in ("accepted", "dropped", "burst", "too few points", "bad fit", "time_surface.quality"):
        assert line in printed, line
    assert "tot spikes" not in printed
    assert main(["eval", str(tmp_path / "rec"), str(out), "--json", str(tmp_path / "eval.json")]) == 0
    scores = json.loads((tmp_path / "eval.json").read_text())
    assert scores["unmatched"] == 0 and scores["matched"] == len(depth) and scores["median_rel_pct"] < 5
    assert main(["compile", "--estimator", "improved"]) == 0
    assert "host      velocity (VelocityProcess), time_surface (TimeSurfaceProcess)" in capsys.readouterr().out
    assert main(["run", str(tmp_path / "rec"), "--spec", "examples/improved.yaml", "--estimator", "paper",
                 "--out", str(tmp_path / "other.npz"), "--quiet"]) != 0
    assert "give one or the other" in capsys.readouterr().err


def test_at_most_one_estimate_per_pixel_and_step_the_first():
    """ON and OFF edges 0.2 ms apart: the second estimate of a pixel in a step is counted same_step."""
    on = moving_pattern(SENSOR, FLOW, 120_000, seed=9, sample_us=50, start_us=1_000)
    off = on.copy()
    off["p"] = 1 - off["p"]
    off["t"] += 200  # the same edges, 0.2 ms later, the other polarity: the same pixels in the same steps
    events = merge_events(on, off)
    result, _ = run(Recording(events, intrinsics=TEST_INTRINSICS, sensor_size=SENSOR), network(), backend="fixed")
    key = result.depth[["step", "x", "y"]]
    assert len(np.unique(key)) == len(key) > 300
    counts = result.counts["time_surface"]
    assert counts["same_step"] > 300 and counts["emitted"] == len(result.depth)
    rejected = sum(counts[r] for r in ts.COUNT_NAMES[ts.NO_MOTION:ts.EMITTED])
    assert counts["accepted"] == rejected + counts["emitted"]
    from_on = np.isin(result.outputs["time_surface.quality"]["t_event"], on["t"])
    assert from_on.mean() > 0.8  # the ON edge comes first; OFF only where its estimate was rejected


def test_the_conformance_cases_exercise_what_they_are_named_for():
    from tofnet.backends.reference import ReferenceBackend
    from tofnet.conformance.cases import get_case

    for name in ("time-surface-texture", "time-surface-rotation"):  # both textures lie at 1 m
        scene = get_case(name).build()
        result = ReferenceBackend().run(scene.network, scene.recording)
        counts = result.counts["time_surface"]
        # (with a rotation every fit is a travel fit, net of it: 2.6 % low here, docs/time_surface.md, 7a, 7h)
        assert len(result.depth) > 400 and abs(np.median(result.depth["z"]) - 1.0) < 0.04, name
        assert counts["burst"] > 500 and counts["bad_fit"] > 20, name
        assert counts["nothing_behind"] + counts["too_few_points"] > 300, name
    assert counts["rotation_dominated"] > 0 and "angular_velocity" in result.counts  # eq. 7 in the second
