"""`tofnet run` on a recording through a distorted lens: undistortion on by default, --no-undistort, and
what `tofnet eval` and `tofnet export` make of the depth file."""

import json
import re

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.io import read_depth, read_recording
from tofnet.io.recording import Intrinsics
from tofnet.sim import generate, scenario
from tofnet.sim.lens import pixel_rays
from tofnet.sim.run import write_result

SIZE = (60, 45)
DAVIS = (-0.368, 0.150, -0.0003, -0.0008, 0.0)


@pytest.fixture(scope="module")
def distorted_folder(tmp_path_factory):
    """A simulated slider seen through the DAVIS240C's lens (rays cast through it), as an ECD folder."""
    config = scenario("slider", 0.25).replace(sensor_size=SIZE)
    k = config.intrinsics
    config = config.replace(intrinsics=Intrinsics(k.fx, k.fy, k.cx, k.cy, DAVIS))
    folder = tmp_path_factory.mktemp("lens") / "slider"
    write_result(generate(config, seed=0), folder)
    return folder


def test_the_simulated_lens_casts_each_pixel_ray_through_the_distortion(distorted_folder):
    from tofnet.kernels.undistort import distort
    k = read_recording(distorted_folder).intrinsics
    assert k.distortion == pytest.approx(DAVIS)  # calib.txt holds the lens
    rays = pixel_rays(k, SIZE)
    x_d, y_d = distort(rays.x, rays.y, "radtan", k.distortion)  # each ray lands back on its pixel
    v, u = np.divmod(np.arange(SIZE[0] * SIZE[1]), SIZE[0])
    assert np.abs(x_d * k.fx + k.cx - u).max() < 1e-9 and np.abs(y_d * k.fy + k.cy - v).max() < 1e-9
    pinhole = pixel_rays(Intrinsics(k.fx, k.fy, k.cx, k.cy), SIZE)
    assert np.array_equal(pinhole.x, ((u - k.cx) / k.fx)) and not pinhole.distorted
    assert rays.fov[0] < pinhole.fov[0] and rays.fov[3] > pinhole.fov[3]  # barrel: the lens sees wider


def test_run_takes_the_lens_into_account_on_raw_pixels_by_default(distorted_folder, tmp_path, capsys):
    out, summary = tmp_path / "depth.npz", tmp_path / "run.json"
    assert main(["run", str(distorted_folder), "--out", str(out), "--json", str(summary), "--quiet"]) == 0
    printed = capsys.readouterr().out
    line = next(text for text in printed.splitlines() if text.startswith("undistort"))
    assert line == "undistort      radtan -0.368 0.15 -0.0003 -0.0008 0: A t through the lens (velocity), raw pixels"
    assert json.loads(summary.read_text())["undistortion"]["velocity"] == "velocity"
    depth, meta = read_depth(out)
    assert meta["latency_steps"] == 2 and meta["summary"]["undistortion"] is None  # raw pixels, the fused chain
    plain = tmp_path / "pinhole.npz"
    assert main(["run", str(distorted_folder), "--out", str(plain), "--no-undistort", "--quiet"]) == 0
    pinhole, _ = read_depth(plain)
    # the same pixels fire (no event moves); the lens changes A t, so the depths differ
    assert len(depth) > 500 and not np.array_equal(depth["z"][:100], pinhole["z"][:100])
    capsys.readouterr()
    assert main(["eval", str(distorted_folder), str(out), "--window", "0", "--json", "-"]) == 0
    assert json.loads(capsys.readouterr().out)["unmatched"] == 0  # matched at the raw pixels they are at


def test_an_undistort_process_moves_the_spikes_and_eval_and_export_follow(distorted_folder, tmp_path, capsys):
    from tofnet.io.spec import dump_spec
    from tofnet.networks import depth_network
    spec = tmp_path / "moved.yaml"
    spec.write_text(dump_spec(depth_network(SIZE, undistort={})))
    out, summary = tmp_path / "depth.npz", tmp_path / "run.json"
    assert main(["run", str(distorted_folder), "--spec", str(spec), "--out", str(out), "--json", str(summary),
                 "--quiet"]) == 0
    printed = capsys.readouterr().out
    line = next(text for text in printed.splitlines() if text.startswith("undistort"))
    counts = json.loads(summary.read_text())["undistortion"]["counts"]
    assert line.startswith("undistort      radtan -0.368 0.15") and f"passed {counts['passed']:,}" in line
    assert counts["passed"] > 1000 and counts["left_image"] > 0
    depth, meta = read_depth(out)
    assert meta["latency_steps"] == 3 and meta["summary"]["undistortion"]["model"] == "radtan"
    assert meta["summary"]["undistortion"]["sensor_size"] == list(SIZE)
    assert main(["eval", str(distorted_folder), str(out), "--window", "0", "--json", "-"]) == 0
    captured = capsys.readouterr()
    scored = json.loads(captured.out)
    assert scored["matched"] == len(depth) and scored["unmatched"] == 0  # matched at their undistorted pixels
    left = re.search(r"note: ([\d,]+) of ([\d,]+) events leave the undistorted image and are not scored", captured.err)
    assert left and 0 < int(left[1].replace(",", "")) < int(left[2].replace(",", ""))  # said, not silently dropped
    plys = {how: tmp_path / f"{how}.ply" for how in ("default", "undistorted", "raw")}
    for how, ply in plys.items():
        assert main(["export", str(out), "--ply", str(ply)] + ([] if how == "default" else ["--pixels", how])) == 0
    # the depth file says its pixels are undistorted: export back-projects them as they are
    assert plys["default"].read_bytes() == plys["undistorted"].read_bytes() != plys["raw"].read_bytes()


def test_no_undistort_treats_the_camera_as_a_pinhole(distorted_folder, tmp_path, capsys):
    out = tmp_path / "raw.npz"
    assert main(["run", str(distorted_folder), "--out", str(out), "--no-undistort", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "undistort      off (--no-undistort): a pinhole, although the recording's lens has radtan" in printed
    _, meta = read_depth(out)
    assert meta["latency_steps"] == 2 and meta["summary"]["undistortion"] is None
