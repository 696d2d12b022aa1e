"""``B ω`` and eq. 7 (tofnet/kernels/rotation.py, the eq. 7 additions of kernels/depth.py).

The sign test projects a static 3-D point at t ± 10 µs and compares its image
velocity with ``B ω`` (pure rotation) and ``A t / Z + B ω`` (rotation and translation).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tofnet.kernels.depth import (EMITTED, NO_MEASUREMENT, ROTATION_DOMINATED, TOO_FAR, TOO_NEAR, classify_rotation,
                                  float_depth, float_depth_rotation, translational_share)
from tofnet.kernels.rotation import rotational_flow, rotational_flow_bound, rotational_flow_grid
from tofnet.kernels.velocity import velocity_term

FX, FY, CX, CY = 210.0, 190.0, 120.5, 88.0  # fx != fy on purpose


def exp_so3(vector: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    angle = float(np.linalg.norm(vector))
    if angle == 0:
        return np.eye(3)
    k = vector / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx


def project(point_camera: np.ndarray) -> np.ndarray:
    x, y, z = point_camera
    return np.array([FX * x / z + CX, FY * y / z + CY])


def image_velocity(point_world, r0, omega, velocity_world, h=1e-5):
    """Central difference of the projection of a static world point, px/s.

    The camera is at ``velocity_world * t`` with orientation ``R_wc(t) = R0 exp(t [ω]×)``
    (``ω`` in the camera frame).
    """
    def at(t):
        r = r0 @ exp_so3(omega * t)
        return project(r.T @ (point_world - velocity_world * t))
    return (at(h) - at(-h)) / (2 * h)


POINTS = [np.array(p) for p in ((0.3, -0.2, 1.5), (-0.9, 0.6, 2.0), (0.05, 0.02, 0.8), (1.2, 0.9, 3.0))]
OMEGAS = [np.array(w) for w in ((0.4, 0.0, 0.0), (0.0, -0.7, 0.0), (0.0, 0.0, 1.1), (0.3, -0.5, 0.8))]


@pytest.mark.parametrize("omega", OMEGAS, ids=str)
@pytest.mark.parametrize("point", POINTS, ids=str)
def test_pure_rotation_moves_a_static_point_by_b_omega(point, omega):
    r0 = exp_so3(np.array([0.1, -0.2, 0.05]))
    point_world = r0 @ point  # ``point`` is where the camera sees it at t = 0
    u, v = project(point)
    expected = image_velocity(point_world, r0, omega, np.zeros(3))
    flow = rotational_flow(*omega, u, v, FX, FY, CX, CY)
    np.testing.assert_allclose(flow, expected, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("omega", OMEGAS, ids=str)
@pytest.mark.parametrize("point", POINTS, ids=str)
def test_rotation_and_translation_give_a_t_over_z_plus_b_omega(point, omega):
    r0 = exp_so3(np.array([-0.3, 0.1, 0.2]))
    velocity_camera = np.array([0.5, -0.2, 0.3])
    point_world = r0 @ point
    u, v = project(point)
    expected = image_velocity(point_world, r0, omega, r0 @ velocity_camera)
    at = np.array(velocity_term(*velocity_camera, u, v, FX, FY, CX, CY))
    flow = at / point[2] + np.array(rotational_flow(*omega, u, v, FX, FY, CX, CY))
    np.testing.assert_allclose(flow, expected, rtol=1e-6, atol=1e-6)


def test_equal_focal_lengths_give_the_textbook_matrix():
    f, x, y = 200.0, 37.0, -21.0
    b = np.array([[x * y / f, -(f + x * x / f), y], [f + y * y / f, -x * y / f, -x]])
    omega = np.array([0.2, -0.3, 0.5])
    np.testing.assert_allclose(rotational_flow(*omega, x + 5.0, y + 7.0, f, f, 5.0, 7.0), b @ omega, rtol=1e-12)


def test_grid_and_bound():
    omega = (0.2, -0.6, 0.4)
    bu, bv = rotational_flow_grid(*omega, 12, 9, FX / 10, FY / 10, 5.5, 4.0)
    assert bu.shape == (9, 12)
    assert (bu[3, 7], bv[3, 7]) == rotational_flow(*omega, 7.0, 3.0, FX / 10, FY / 10, 5.5, 4.0)
    assert np.hypot(bu, bv).max() <= rotational_flow_bound(*omega, 12, 9, FX / 10, FY / 10, 5.5, 4.0)


def test_eq7_recovers_depth_from_exact_timings():
    # An edge moving along u: flow_u = (A t)_u / Z + (B ω)_u, td_u = 1 / flow_u.
    z_true, at_u, bw_u = 1.7, -110.0, -25.0
    flow = at_u / z_true + bw_u
    seconds_per_count = 1e-4
    counts = 1.0 / flow / seconds_per_count  # fractional: the exact td
    share = translational_share(counts, 0, bw_u, 0.0, seconds_per_count)
    assert share == pytest.approx((at_u / z_true) / flow)
    assert float_depth_rotation(counts, 0, at_u, 0.0, bw_u, 0.0, seconds_per_count) == pytest.approx(z_true)
    # eq. 8 is eq. 7 without rotation, and misreads the rotation as depth.
    assert float_depth_rotation(counts, 0, at_u, 0.0, 0.0, 0.0, seconds_per_count) == \
        float_depth(counts, 0, at_u, 0.0, seconds_per_count)
    assert float_depth(counts, 0, at_u, 0.0, seconds_per_count) == pytest.approx(z_true * share)


def test_timing_error_is_amplified_by_one_over_share():
    z_true, at_u, seconds_per_count, e = 2.0, -100.0, 1e-4, 1e-3
    for bw_u in (0.0, -20.0, -100.0, 30.0):
        flow = at_u / z_true + bw_u
        counts = 1.0 / flow / seconds_per_count
        r = translational_share(counts, 0, bw_u, 0.0, seconds_per_count)
        z = float_depth_rotation(counts * (1 + e), 0, at_u, 0.0, bw_u, 0.0, seconds_per_count)
        assert (z - z_true) / z_true == pytest.approx(e / r, rel=0.05)


def test_classify_rotation_order():
    assert classify_rotation(False, -1.0, 1.0, 0.1, 0.1, 10.0) == NO_MEASUREMENT
    assert classify_rotation(True, 0.1, 1.0, 0.1, 0.1, 10.0) == ROTATION_DOMINATED
    assert classify_rotation(True, -0.5, -3.0, 0.0, 0.1, 10.0) == ROTATION_DOMINATED
    assert classify_rotation(True, 0.5, 0.05, 0.1, 0.1, 10.0) == TOO_NEAR
    assert classify_rotation(True, 0.5, 12.0, 0.1, 0.1, 10.0) == TOO_FAR
    assert classify_rotation(True, 0.5, 2.0, 0.1, 0.1, 10.0) == EMITTED
    assert classify_rotation(True, 3, 200, 2, 10, 1000) == EMITTED  # integers (fixed point)
    assert float_depth_rotation(1, 0, -100.0, 0.0, 1000.0, 0.0, 1e-3) == math.inf  # share exactly 0
