"""Undistortion maths: forward models as OpenCV writes them, their inverse, the event remap."""

import numpy as np
import pytest

from tofnet.events import make_events
from tofnet.io.recording import Intrinsics
from tofnet.kernels.undistort import distort, remap_events, undistort, undistortion_map
from optional import optional

#: ECD slider_depth's DAVIS240C (strong barrel: k1 = -0.37) and a DSEC-like fisheye lens.
DAVIS = Intrinsics(199.092366542, 198.82882047, 132.192071378, 110.712660011,
                   (-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0))
FISHEYE = Intrinsics(555.6, 555.1, 342.3, 218.0, (-0.04, 0.01, -0.003, 0.0006), "equidistant")
CASES = [(DAVIS, (240, 180)), (FISHEYE, (640, 480))]


def _grid(size):
    v, u = np.mgrid[0:size[1], 0:size[0]].astype(np.float64)
    return u, v


def test_forward_models_written_out_by_hand():
    x, y = 0.3, -0.2
    k1, k2, p1, p2, k3 = 0.1, -0.02, 0.003, -0.004, 0.005
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    expected = (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
    assert np.allclose(distort(x, y, "radtan", (k1, k2, p1, p2, k3)), expected, rtol=0, atol=1e-15)
    theta = np.arctan(np.hypot(x, y))
    theta_d = theta * (1 + 0.1 * theta ** 2 - 0.02 * theta ** 4 + 0.003 * theta ** 6 - 0.004 * theta ** 8)
    scale = theta_d / np.hypot(x, y)
    assert np.allclose(distort(x, y, "equidistant", (0.1, -0.02, 0.003, -0.004)), (x * scale, y * scale), atol=1e-15)


@pytest.mark.parametrize("intrinsics, size", CASES)
def test_map_round_trips_through_the_forward_model(intrinsics, size):
    pixel_map = undistortion_map(intrinsics, size)
    assert not np.isnan(pixel_map).any()
    x = (pixel_map[..., 0] - intrinsics.cx) / intrinsics.fx
    y = (pixel_map[..., 1] - intrinsics.cy) / intrinsics.fy
    x_d, y_d = distort(x, y, intrinsics.distortion_model, intrinsics.distortion)
    u, v = _grid(size)
    assert np.abs(x_d * intrinsics.fx + intrinsics.cx - u).max() < 1e-9
    assert np.abs(y_d * intrinsics.fy + intrinsics.cy - v).max() < 1e-9
    # barrel distortion: the corners move outwards
    assert pixel_map[0, 0, 0] < 0 and pixel_map[0, 0, 1] < 0


@pytest.mark.parametrize("intrinsics, size", CASES)
def test_inverse_agrees_with_a_generic_numerical_inverse(intrinsics, size):
    """Gauss-Newton with a finite-difference Jacobian, independent of the analytic one."""
    rng = np.random.default_rng(0)
    u, v = rng.uniform(0, size[0] - 1, 200), rng.uniform(0, size[1] - 1, 200)
    x_d, y_d = (u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy
    model, coefficients = intrinsics.distortion_model, intrinsics.distortion
    x, y = x_d.copy(), y_d.copy()
    h = 1e-7
    for _ in range(50):
        f = np.stack(distort(x, y, model, coefficients)) - np.stack([x_d, y_d])
        jx = (np.stack(distort(x + h, y, model, coefficients)) - np.stack(distort(x - h, y, model, coefficients))) / (2 * h)
        jy = (np.stack(distort(x, y + h, model, coefficients)) - np.stack(distort(x, y - h, model, coefficients))) / (2 * h)
        det = jx[0] * jy[1] - jy[0] * jx[1]
        x, y = x - (jy[1] * f[0] - jy[0] * f[1]) / det, y - (jx[0] * f[1] - jx[1] * f[0]) / det
    ours = undistort(x_d, y_d, model, coefficients)
    assert np.abs(ours[0] - x).max() * intrinsics.fx < 1e-6 and np.abs(ours[1] - y).max() * intrinsics.fy < 1e-6


@pytest.mark.parametrize("intrinsics, size", CASES)
def test_against_opencv_when_installed(intrinsics, size):
    cv2 = optional("cv2")
    k = np.array([[intrinsics.fx, 0, intrinsics.cx], [0, intrinsics.fy, intrinsics.cy], [0, 0, 1]])
    u, v = _grid(size)
    points = np.stack([u, v], axis=-1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    if intrinsics.distortion_model == "radtan":
        expected = cv2.undistortPoints(points, k, np.array(intrinsics.distortion), R=np.eye(3), P=k, criteria=criteria)
    else:
        expected = cv2.fisheye.undistortPoints(points, k, np.array(intrinsics.distortion), P=k, criteria=criteria)
    assert np.abs(undistortion_map(intrinsics, size) - expected.reshape(size[1], size[0], 2)).max() < 1e-8


def test_points_beyond_the_fold_have_no_inverse():
    # r(1 - 0.5 r²) peaks at 0.544 for r = 0.816: distorted radii beyond have no preimage.
    x, y = undistort(np.array([0.3, 0.6]), np.array([0.0, 0.0]), "radtan", (-0.5, 0, 0, 0, 0))
    assert np.isfinite(x[0]) and np.isnan(x[1]) and np.isnan(y[1])


def test_remap_rounds_to_nearest_and_counts_what_leaves():
    size = (240, 180)
    pixel_map = undistortion_map(DAVIS, size)
    events = make_events([1, 2, 3, 4, 5], [0, 132, 239, 10, 300], [0, 110, 179, 90, 5], [1, 0, 1, 0, 1])
    out, counts = remap_events(events, pixel_map)
    inside = np.floor(pixel_map[events["y"][:4], events["x"][:4]] + 0.5)
    keep = (inside[:, 0] >= 0) & (inside[:, 1] >= 0) & (inside[:, 0] < 240) & (inside[:, 1] < 180)
    assert counts == {"left_image": int((~keep).sum()), "beyond_map": 1}
    assert len(out) + counts["left_image"] + counts["beyond_map"] == len(events)
    assert np.array_equal(out["x"], inside[keep, 0].astype(np.uint16))
    assert np.array_equal(out["y"], inside[keep, 1].astype(np.uint16))
    assert np.array_equal(out["t"], events["t"][:4][keep]) and np.array_equal(out["p"], events["p"][:4][keep])
    assert counts["left_image"] >= 1  # the corner pixel (0, 0) moves out of the image
