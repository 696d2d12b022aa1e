"""UndistortProcess: declaration, the remap on every backend, its counts, networks, specs and evaluation."""

import contextlib

import numpy as np
import pytest

from tofnet.api import default_network, lens_is_distorted, load_network, run
from tofnet.backends.registry import available_backends, get_backend
from tofnet.cli import main
from tofnet.compiler import compile_network
from tofnet.conformance import BackendRunner
from tofnet.core.network import Network
from tofnet.errors import DataError, NetworkError
from tofnet.eval.undistorted import undistorted_recording
from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Intrinsics, Recording
from tofnet.io.spec import dump_spec, load_spec, networks_equal
from tofnet.kernels.undistort import pixel_targets, remap_events, undistortion_map
from tofnet.networks import depth_network
from tofnet.processes import InputProcess, UndistortProcess
from tofnet.testing import merge_events, moving_pattern, step_events

SENSOR = (24, 16)
#: Barrel (pixels move outwards, corners leave the image) and pincushion (pixels crowd: merges).
BARREL = Intrinsics(20.0, 20.0, 11.5, 7.5, (-0.3, 0.1, 0.001, -0.002, 0.0))
PINCUSHION = Intrinsics(20.0, 20.0, 11.5, 7.5, (0.3, 0.0, 0.0, 0.0, 0.0))
VELOCITY = {"source": "constant", "velocity": [-0.5, 0.2, 0.1], "per": "pixel"}


def remap_network(**undistort) -> Network:
    inp = InputProcess(name="input", sensor_size=SENSOR, refractory=0, t0=0)
    lens = UndistortProcess(name="undistort", **undistort)
    inp.events.connect(lens.events)
    return Network([inp, lens], name="remap")


def texture(intrinsics: Intrinsics) -> Recording:
    events = merge_events(moving_pattern(SENSOR, (300, -150), 150_000, seed=3),
                          moving_pattern(SENSOR, (-200, 100), 150_000, seed=4))
    return Recording(events, intrinsics=intrinsics)


def expected_remap(spikes: np.ndarray, intrinsics: Intrinsics) -> tuple[np.ndarray, int]:
    """What the process must send for the input's spikes: ``remap_events`` step by step, the first spike
    per undistorted pixel kept (canonical order), sorted by (step, y, x); and how many merged."""
    events = np.zeros(len(spikes), EVENT_DTYPE)
    events["t"], events["x"], events["y"], events["p"] = spikes["step"] + 1, spikes["x"], spikes["y"], spikes["p"]
    moved, _ = remap_events(events, undistortion_map(intrinsics, SENSOR))
    key = moved["t"] * (1 << 32) + moved["y"].astype(np.int64) * SENSOR[0] + moved["x"]
    _, first = np.unique(key, return_index=True)
    return moved[first], len(moved) - len(first)


def test_the_declaration_checks_its_lens():
    assert UndistortProcess.placement == "host" and UndistortProcess.resources_per_pixel == {}
    with pytest.raises(NetworkError, match="undistort.coefficients: needed with model"):
        UndistortProcess(name="undistort", model="radtan")
    with pytest.raises(NetworkError, match="equidistant model takes 4 numbers, got 5"):
        UndistortProcess(model="equidistant", coefficients=[0.1, 0, 0, 0, 0])
    with pytest.raises(NetworkError, match="expected one of radtan, equidistant"):
        UndistortProcess(model="fisheye", coefficients=[0.1, 0, 0, 0])
    with pytest.raises(NetworkError, match="focal lengths"):
        UndistortProcess(intrinsics=[0, 20, 1, 1])
    own = UndistortProcess(model="radtan", coefficients=[-0.3, 0.1, 0, 0], intrinsics=[30, 31, 5, 6])
    assert own.lens(BARREL) == Intrinsics(30, 31, 5, 6, (-0.3, 0.1, 0, 0, 0.0), "radtan")  # k3 = 0 added
    assert UndistortProcess().lens(BARREL) == BARREL
    with pytest.raises(DataError, match="no camera calibration.*'undistort' needs fx, fy, cx, cy"):
        UndistortProcess().lens(None)


def test_it_costs_no_core_and_one_step_of_latency():
    compiled = compile_network(depth_network(SENSOR, undistort={}, velocity=VELOCITY), patch=(8, 8))
    assert "undistort" in compiled.host and "undistort" not in [layer.name for layer in compiled.layers]
    plain = compile_network(depth_network(SENSOR, velocity=VELOCITY), patch=(8, 8))
    assert len(compiled.cores) == len(plain.cores)
    result = get_backend("fixed").run(compiled, texture(BARREL))
    assert result.latency_steps == 3


@pytest.fixture(scope="module", params=available_backends())
def backend(request):
    with contextlib.ExitStack() as stack:
        yield BackendRunner(get_backend(request.param), stack)


@pytest.mark.parametrize("intrinsics", [BARREL, PINCUSHION], ids=["barrel", "pincushion"])
def test_every_backend_moves_every_spike_as_remap_events_does(backend, intrinsics):
    result = backend.run(compile_network(remap_network()), texture(intrinsics), record_tot=False,
                         probes=["input.events"])
    sent, merged = expected_remap(result.outputs["input.events"], intrinsics)
    out = result.outputs["undistort.undistorted"]
    assert np.array_equal(out["step"], sent["t"]) and np.array_equal(out["x"], sent["x"])
    assert np.array_equal(out["y"], sent["y"]) and np.array_equal(out["p"], sent["p"])
    counts = result.counts["undistort"]
    assert counts["merged"] == merged and counts["passed"] == len(out)
    assert sum(counts.values()) == len(result.outputs["input.events"])
    if intrinsics is BARREL:
        assert counts["left_image"] > 0 and merged == 0
    else:
        assert merged > 0 and counts["left_image"] == 0


def test_the_depth_network_is_bit_exact_across_integer_backends_and_equal_in_float(backend):
    compiled = compile_network(depth_network(SENSOR, input={"refractory": 0}, undistort={}, velocity=VELOCITY),
                               patch=(8, 8))
    recording = texture(BARREL)
    result = backend.run(compiled, recording)
    reference = get_backend("fixed" if backend.arithmetic == "fixed" else "reference").run(compiled, recording)
    assert len(result.depth) > 100
    assert result.depth.tobytes() == reference.depth.tobytes()
    assert result.counts["undistort"] == reference.counts["undistort"]


def test_merged_keeps_the_first_spike_in_canonical_order_and_left_image_counts_the_rest():
    targets = pixel_targets(undistortion_map(PINCUSHION, SENSOR))
    flat = targets.ravel()
    values, counts = np.unique(flat[flat >= 0], return_counts=True)
    shared = values[counts > 1][0]  # an undistorted pixel two raw pixels land on
    (y0, x0), (y1, x1) = (divmod(int(i), SENSOR[0]) for i in np.flatnonzero(flat == shared)[:2])
    events = step_events([(2, x0, y0, 1), (2, x1, y1, 0), (5, x1, y1, 0)])
    result, _ = run(Recording(events, intrinsics=PINCUSHION), remap_network(), backend="fixed")
    out = result.outputs["undistort.undistorted"]
    assert result.counts["undistort"] == {"passed": 2, "left_image": 0, "merged": 1}
    assert out["p"].tolist() == [1, 0] and out["step"].tolist() == [3, 6]  # the first raw pixel's ON spike
    corner = step_events([(1, 0, 0, 1)])
    result, _ = run(Recording(corner, intrinsics=BARREL), remap_network(), backend="reference")
    assert targets[0, 0] >= 0 and pixel_targets(undistortion_map(BARREL, SENSOR))[0, 0] == -1
    assert result.counts["undistort"] == {"passed": 0, "left_image": 1, "merged": 0}


def test_networks_with_the_process_see_a_pinhole_and_never_correct_the_lens_twice(tmp_path):
    distorted, pinhole = texture(BARREL), texture(Intrinsics(20.0, 20.0, 11.5, 7.5, (0.0,) * 5))
    assert lens_is_distorted(distorted) and not lens_is_distorted(pinhole) and not lens_is_distorted(None)
    # the default network keeps raw pixels (its velocity process sees the lens): no undistort process
    assert [p.name for p in default_network(distorted).processes] == ["input", "time_of_travel", "depth", "velocity"]
    assert depth_network(SENSOR, undistort={}).process("velocity").distortion_model == "none"
    spec = tmp_path / "twice.yaml"
    spec.write_text(dump_spec(depth_network(SENSOR, undistort={}, velocity=VELOCITY)).replace(
        ", distortion_model: none", ""))
    with pytest.raises(NetworkError, match="also takes the lens into account; set distortion_model: none"):
        load_network(spec, recording=distorted)
    load_network(spec, recording=pinhole)  # no lens: nothing to correct twice


def test_specs_declare_it_round_trip_it_and_no_undistort_refuses_it(tmp_path, capsys):
    network = depth_network(SENSOR, undistort={"model": "equidistant", "coefficients": [-0.04, 0.01, 0, 0.001]})
    assert networks_equal(load_spec(dump_spec(network)).network, network)
    spec = tmp_path / "lens.yaml"
    spec.write_text("processes:\n"
                    "  input: {type: InputProcess, sensor_size: [24, 16]}\n"
                    "  undistort: {type: Undistort}\n"
                    "  time_of_travel: {type: TimeOfTravelProcess}\n"
                    "connections:\n"
                    "  - input.events -> undistort.events\n"
                    "  - undistort.undistorted -> time_of_travel.events\n")
    loaded = load_network(spec)[0]
    assert isinstance(loaded.process("undistort"), UndistortProcess)
    with pytest.raises(NetworkError, match="the spec undistorts .*remove it from the spec"):
        load_network(spec, undistort=False)
    assert main(["compile", str(spec)]) == 0
    report = capsys.readouterr().out
    assert "host      input (InputProcess), undistort (UndistortProcess)" in report  # on no core


def test_evaluation_moves_the_events_and_their_ground_truth_together():
    recording = texture(BARREL)
    recording.gt_depth = np.arange(len(recording.events), dtype=np.float64)
    moved = undistorted_recording(recording, BARREL, SENSOR)
    targets = pixel_targets(undistortion_map(BARREL, SENSOR))
    index = moved.gt_depth.astype(np.int64)  # which original event each one is
    original = recording.events[index]
    assert np.array_equal(moved.events["t"], original["t"])
    assert np.array_equal(moved.events["y"].astype(np.int64) * SENSOR[0] + moved.events["x"],
                          targets[original["y"], original["x"]])
    assert len(moved.events) == np.count_nonzero(targets[recording.events["y"], recording.events["x"]] >= 0)
