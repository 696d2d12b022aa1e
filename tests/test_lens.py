"""A distorted lens in the velocity term: ``J A(p') t`` per sample, the same on every backend, and more accurate."""

import numpy as np
import pytest

from tofnet.api import run
from tofnet.backends.registry import get_backend
from tofnet.errors import NetworkError
from tofnet.eval.metrics import evaluate
from tofnet.io.recording import Intrinsics, Recording
from tofnet.kernels.lens import lens_jacobian, lens_of, sample_table
from tofnet.kernels.undistort import undistort
from tofnet.models.velocity import VelocityField
from tofnet.networks import depth_network
from tofnet.processes import VelocityProcess
from tofnet.testing import merge_events, moving_pattern

DAVIS = (-0.368, 0.150, -0.0003, -0.0008, 0.0)
CAMERA = (40.0, 41.0, 19.5, 14.5)
SENSOR = (40, 30)


def test_the_jacobian_takes_ideal_displacements_onto_the_sensor():
    u, v = np.meshgrid(np.arange(0.0, 40.0, 3.0), np.arange(0.0, 30.0, 3.0))
    table = lens_jacobian(u, v, CAMERA, ("radtan", DAVIS))
    fx, fy, cx, cy = CAMERA

    def ideal(du, dv):
        x, y = undistort((u + du - cx) / fx, (v + dv - cy) / fy, "radtan", DAVIS)
        return np.stack([fx * x + cx, fy * y + cy])

    assert np.allclose(table[..., 0], ideal(0, 0)[0], atol=1e-9) and np.allclose(table[..., 1], ideal(0, 0)[1])
    h = 1e-4  # d ideal / d raw, numerically: J must be its inverse
    d_ideal = np.stack([(ideal(h, 0) - ideal(-h, 0)) / (2 * h), (ideal(0, h) - ideal(0, -h)) / (2 * h)], axis=1)
    j = table[..., 2:].reshape(table.shape[:-1] + (2, 2))
    product = np.einsum("...ij,jk...->...ik", j, d_ideal)
    assert np.abs(product - np.eye(2)).max() < 1e-6
    assert np.abs(j - np.eye(2)).max() > 0.1  # the lens is strong at the corners


def test_without_distortion_the_table_is_the_pinhole_exactly():
    assert lens_of(Intrinsics(*CAMERA)) is None and lens_of(Intrinsics(*CAMERA, (0.0,) * 5)) is None
    table = sample_table(False, 7, SENSOR, CAMERA, None)
    assert np.all(table[..., 2:] == (1.0, 0.0, 0.0, 1.0)) and not table.flags.writeable
    field = VelocityField(False, 7, CAMERA, SENSOR)
    lensed = VelocityField(False, 7, CAMERA, SENSOR, ("radtan", DAVIS))
    t = (-0.4, 0.1, 0.2)
    plain = field.dense(t)
    assert np.array_equal(plain[0][0, :3], -CAMERA[0] * t[0] + (np.array([3.0, 3.0, 3.0]) - CAMERA[2]) * t[2])
    assert not np.allclose(lensed.dense(t)[0], plain[0])


def texture(intrinsics):
    events = merge_events(moving_pattern(SENSOR, (300, -120), 200_000, seed=5),
                          moving_pattern(SENSOR, (-150, 80), 200_000, seed=6))
    return Recording(events, intrinsics=intrinsics, sensor_size=SENSOR)


@pytest.mark.parametrize("per", ["patch", "pixel"])
def test_every_backend_computes_the_same_depths_through_the_lens(per):
    recording = texture(Intrinsics(*CAMERA, DAVIS))
    net = depth_network(SENSOR, input={"refractory": "2ms"}, velocity={"source": "constant",
                        "velocity": [-0.4, 0.15, 0.2], "per": per, "patch_size": 7})
    runs = {label: get_backend(name, **options).run(net, recording).depth for label, name, options in
            (("fused", "fixed", {}), ("unfused", "fixed", {"fuse": False}), ("multiproc", "multiproc", {"workers": 2}),
             ("float", "float", {}), ("reference", "reference", {}))}
    fixed = runs["fused"]
    assert len(fixed) > 200
    # bit for bit across the integer backends, fused or not
    assert runs["unfused"].tobytes() == fixed.tobytes() and runs["multiproc"].tobytes() == fixed.tobytes()
    assert np.array_equal(runs["float"][["x", "y", "step"]], runs["reference"][["x", "y", "step"]])
    assert np.allclose(runs["float"]["z"], runs["reference"]["z"], rtol=1e-12, atol=0)
    pinhole = get_backend("fixed").run(net, texture(Intrinsics(*CAMERA))).depth
    assert len(pinhole) != len(fixed) or not np.array_equal(pinhole["z"], fixed["z"])  # the lens changes depths


def test_a_simulated_lens_is_measured_like_a_pinhole_only_through_the_lens():
    from tofnet.sim import generate, scenario
    config = scenario("slider", 0.3).replace(sensor_size=(160, 120))
    k = config.intrinsics
    recording = generate(config.replace(intrinsics=Intrinsics(k.fx, k.fy, k.cx, k.cy, DAVIS)), seed=0).to_recording()
    medians = {}
    for name, velocity in (("lens", {}), ("ignored", {"distortion_model": "none"})):
        result, _ = run(recording, depth_network(recording.sensor_size, velocity=velocity))
        meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
        medians[name] = evaluate(recording, result.depth, meta, window_s=0).errors.median_rel_pct
    # 0.3 s at 160x120 (seed 0): 26.7 % through the lens, 31.7 % ignoring it (benchmarks/undistort_accuracy.py)
    assert medians["lens"] < medians["ignored"] - 2.0, medians


def test_the_velocity_process_checks_its_lens():
    with pytest.raises(NetworkError, match="distortion: radtan takes 4 or 5 coefficients, got 3"):
        VelocityProcess(name="v", distortion_model="radtan", distortion=[0.1, 0.2, 0.3])
    with pytest.raises(NetworkError, match="distortion: needs distortion_model: radtan or equidistant"):
        VelocityProcess(name="v", distortion=[0.1, 0.2, 0.3, 0.4])
    with pytest.raises(NetworkError, match="distortion_model: equidistant needs distortion"):
        VelocityProcess(name="v", distortion_model="equidistant")


def test_the_time_surface_takes_the_lens_too():
    from tofnet.networks import improved_network
    recording = texture(Intrinsics(*CAMERA, DAVIS))
    velocity = {"source": "constant", "velocity": [-0.4, 0.15, 0.2]}
    lens = get_backend("fixed").run(improved_network(SENSOR, velocity=velocity), recording).depth
    pinhole = get_backend("fixed").run(improved_network(SENSOR, velocity={**velocity, "distortion_model": "none"}),
                                       recording).depth
    assert len(lens) > 100 and len(pinhole) > 100
    assert lens.tobytes() != pinhole.tobytes()  # the fits use the motion direction and depth J A(p') t
