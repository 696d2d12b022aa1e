"""Figures: the data they show, their labels and units, the PNGs, and ``tofnet plot``."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError, TofnetError
from tofnet.eval import evaluate
from tofnet.eval.bins import band_window_s, depth_lattice, histogram_edges, ray_medians, window_quartiles
from tofnet.eval.plots import (DPI, FIGURE_SIZES, cloud_figure, depth_map_figure, error_figure, histogram_figure,
                               plot_all, save_figure)
from tofnet.eval.views import (Window, back_project, depth_image, resolve_window, to_world, world_points)
from tofnet.events import DEPTH_DTYPE, EVENT_DTYPE
from tofnet.io import write_depth, write_ecd
from tofnet.io.groundtruth import Trajectory
from tofnet.io.recording import Intrinsics, Recording

META = {"t0_us": 0, "timestep_us": 1000, "latency_steps": 2}
SIZE = (40, 30)


def scene(seed: int = 0, n: int = 4000, duration_us: int = 400_000, gt: bool = True, poses: bool = True):
    """A small recording: three depth planes, a sideways camera, estimates for every other event."""
    rng = np.random.default_rng(seed)
    width, height = SIZE
    plane = np.full((height, width), 4.0)
    plane[5:20, 5:15] = 1.0
    plane[10:28, 22:35] = 2.0
    events = np.empty(n, EVENT_DTYPE)
    events["t"] = np.sort(rng.integers(0, duration_us, n))
    events["x"], events["y"] = rng.integers(0, width, n), rng.integers(0, height, n)
    events["p"] = rng.integers(0, 2, n)
    true = plane[events["y"], events["x"]]
    idx = np.flatnonzero(rng.random(n) < 0.5)
    depth = np.empty(len(idx), DEPTH_DTYPE)
    depth["step"] = events["t"][idx] // 1000 + 2
    depth["t"] = (depth["step"] + 1) * 1000
    depth["x"], depth["y"] = events["x"][idx], events["y"][idx]
    depth["z"] = true[idx] * np.exp(rng.normal(0, 0.1, len(idx)))
    times = np.linspace(0, duration_us * 1e-6, 5)
    trajectory = Trajectory(times, np.column_stack([0.5 * times, 0 * times, 0.1 * times]),
                            np.tile([0, 0, 0, 1.0], (5, 1))) if poses else None
    rec = Recording(events=events, intrinsics=Intrinsics(30.0, 30.0, 20.0, 15.0), trajectory=trajectory,
                    sensor_size=SIZE, gt_depth=true if gt else None, source="scene")
    return rec, depth


def png_size(path: Path) -> tuple[int, int]:
    """Width and height from the PNG header (IHDR)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def labels(fig) -> list[str]:
    return [text for ax in fig.axes for text in (ax.get_xlabel(), ax.get_ylabel()) if text]


def expected_pixels(kind: str) -> tuple[int, int]:
    w, h = FIGURE_SIZES[kind]
    return round(w * DPI), round(h * DPI)


def test_depth_image_takes_the_latest_or_the_median_depth_per_pixel():
    x, y = np.array([1, 1, 1, 2]), np.array([0, 0, 0, 1])
    z, t = np.array([3.0, 1.0, 2.0, 5.0]), np.array([5, 9, 7, 1])
    latest = depth_image(x, y, z, t, (3, 2), "latest")
    assert latest[0, 1] == 1.0 and latest[1, 2] == 5.0
    assert np.isnan(latest).sum() == 4  # unmeasured pixels stay empty
    assert depth_image(x, y, z, t, (3, 2), "median")[0, 1] == 2.0
    assert depth_image(x[:2], y[:2], z[:2], t[:2], (3, 2), "median")[0, 1] == 2.0  # mean of the two middle


def test_windows_from_specs():
    span = (1_000_000, 3_000_000)
    assert resolve_window("0.2:0.27", span, default_s=None) == Window(1_200_000, 1_270_000, 1_000_000)
    assert resolve_window("200ms:270ms", span, default_s=None) == Window(1_200_000, 1_270_000, 1_000_000)
    centred = resolve_window("70ms", span, default_s=None)
    assert (centred.start_us, centred.end_us) == (1_965_000, 2_035_000)
    assert resolve_window(None, span, default_s=0.07) == centred
    whole = resolve_window(None, span, default_s=None)
    assert whole.whole and "whole run" in whole.label()
    assert "70 ms" in centred.label()
    for bad in ("0.3:0.2", "-5ms", "soon"):
        with pytest.raises(TofnetError):
            resolve_window(bad, span, default_s=None)
    assert resolve_window("1.5:2.5", span, default_s=None) == Window(2_500_000, 3_500_000, 1_000_000)  # in part
    for outside in ("5:6", "2:3", "-2:0"):  # the span is 0 .. 2 s since its start: an empty figure
        with pytest.raises(TofnetError, match=rf"window '{outside}': outside the span of the events and estimates, "
                                              r"0 \.\. 2 s since its start"):
            resolve_window(outside, span, default_s=None)


def test_a_default_window_with_few_estimates_is_widened_and_says_so():
    """A real recording's 1,078 estimates over 10.8 s put one in the default 70 ms: a black depth map."""
    from tofnet.eval.views import widened_window
    span = (1_000_000, 3_000_000)
    centred = resolve_window(None, span, default_s=0.07)
    dense = np.arange(1_000_000, 3_000_000, 10)  # 7,000 stamps in the 70 ms
    assert widened_window(centred, span, dense, 500) == centred and centred.note() == ""
    sparse = np.arange(1_000_000, 3_000_000, 1_000)  # 70 in the 70 ms, 2,000 in all
    wider = widened_window(centred, span, sparse, 500)
    assert wider.end_us - wider.start_us == 560_000 and wider.start_us < 2_000_000 < wider.end_us
    assert np.count_nonzero((sparse >= wider.start_us) & (sparse < wider.end_us)) >= 500
    assert "widened from the default 70 ms" in wider.note() and "560 ms" in wider.label()
    whole = widened_window(centred, span, sparse[:100], 500)
    assert whole.whole and (whole.start_us, whole.end_us) == span and whole.widened_from_s == pytest.approx(0.07)


def test_back_projection_and_world_transform():
    intr = Intrinsics(100.0, 50.0, 10.0, 20.0)
    cam = back_project(np.array([110]), np.array([20]), np.array([2.0]), intr)
    assert cam.tolist() == [[2.0, 0.0, 2.0]]  # one focal length right of centre: X = z
    # Camera at (1, 2, 3), turned 90 degrees about y: its z axis points along world +x.
    r = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    world = to_world(cam, np.array([[1.0, 2, 3]]), r[None])
    assert world == pytest.approx(np.array([[3.0, 2.0, 1.0]]))


def test_world_points_use_the_pose_at_the_given_time():
    traj = Trajectory([0.0, 1.0], [[0, 0, 0], [1.0, 0, 0]], [[0, 0, 0, 1.0], [0, 0, 0, 1.0]])
    depth = np.zeros(1, DEPTH_DTYPE)
    depth["x"], depth["y"], depth["z"], depth["t"] = 20, 15, 2.0, 500_000
    pts = world_points(depth, Intrinsics(30.0, 30.0, 20.0, 15.0), traj)
    assert pts == pytest.approx(np.array([[0.5, 0.0, 2.0]]))
    with pytest.raises(DataError, match="poses"):
        world_points(depth, Intrinsics(1, 1, 0, 0), None)


def test_depth_map_figure_shows_the_window_with_ground_truth():
    rec, depth = scene()
    fig = depth_map_figure(rec, depth, META, window="100ms:200ms")
    est_ax, gt_ax = fig.axes[:2]
    shown = np.ma.filled(est_ax.images[0].get_array(), np.nan)
    sel = depth[(depth["t"] >= 100_000) & (depth["t"] < 200_000)]
    assert shown.shape == (SIZE[1], SIZE[0])
    np.testing.assert_array_equal(shown, depth_image(sel["x"], sel["y"], sel["z"], sel["t"], SIZE))
    assert gt_ax.images  # ground-truth panel
    assert "x [px]" in labels(fig) and "y [px]" in labels(fig)
    assert fig.axes[-1].get_ylabel() == "depth [m]"  # the colour bar
    assert "100 ms" in fig.get_suptitle() and "0.100" in fig.get_suptitle()
    one = depth_map_figure(rec, depth, META, with_gt=False)
    assert len([ax for ax in one.axes if ax.images]) == 1 and "70 ms" in one.get_suptitle()


def test_histogram_counts_every_estimate_and_overlays_the_matched_truth():
    rec, depth = scene()
    fig = histogram_figure(rec, depth, META)
    ax = fig.axes[0]
    shown = sum(bar.get_height() for bar in ax.containers[0])  # the estimates' bars
    beyond = int(np.count_nonzero(depth["z"] > ax.get_xlim()[1]))
    assert shown + beyond == len(depth) and shown > 0.9 * len(depth)
    assert ax.get_xlabel() == "depth [m]" and ax.get_ylabel().endswith(" m bin")
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == [f"estimates ({len(depth):,})", f"ground truth of the same events ({len(depth):,})"]
    assert "whole run" in ax.get_title()


def test_error_figure_plots_the_windowed_median_beside_the_trajectory():
    rec, depth = scene()
    fig = error_figure(rec, depth, META, window_s=0.1)
    position, velocity, error = fig.axes[:3]
    assert position.get_ylabel() == "position (world) [m]"
    assert velocity.get_ylabel() == "velocity (camera) [m/s]"
    assert error.get_ylabel() == "relative error [%]"
    assert error.get_xlabel() == "time since start [s]"
    median = next(line for line in error.get_lines() if line.get_label() == "median")
    expected = [w.errors.median_rel_pct for w in evaluate(rec, depth, META, window_s=0.1).windows]
    assert median.get_ydata()[:4] == pytest.approx(expected)  # the fifth window (0.4-0.402 s) is too thin
    assert np.isnan(median.get_ydata()[4:]).all()
    assert median.get_xdata()[:4] == pytest.approx([0.05, 0.15, 0.25, 0.35])
    x_line = position.get_lines()[0]
    assert x_line.get_ydata()[-1] == pytest.approx(0.5 * 0.402, abs=1e-3)  # x = 0.5 m/s * t


def test_cloud_figure_draws_one_point_per_ray_cell_and_every_estimate_from_above():
    rec, depth = scene()
    fig = cloud_figure(rec, depth, META)
    ax, top = fig.axes[0], fig.axes[2]
    assert ax.name == "3d"
    assert ax.get_xlabel() == "x, right [m]" and ax.get_ylabel() == "z, forward [m]" and "[m]" in ax.get_zlabel()
    assert fig.axes[1].get_ylabel() == "depth [m]"
    # The camera never turns and starts at the origin: the first pose's frame is the world's.
    world = world_points(depth, rec.intrinsics, rec.trajectory, depth["step"] * 1000 - 2000 + 500)
    cells, _, spread = ray_medians(world, 3 / rec.intrinsics.fx, 3)
    agree = cells[spread <= 0.3]
    drawn = np.ma.filled(ax.collections[0].get_array(), np.nan)  # the colour of a point is its median depth
    assert 0 < len(agree) < len(cells) and 0.9 * len(agree) <= len(drawn) <= len(agree)
    assert np.isin(drawn, agree[:, 2]).all()
    assert f"{len(cells) - len(agree):,} others disagree" in ax.get_title()
    assert top.get_xlabel() == "x, right [m]" and top.get_ylabel() == "z, forward [m]"
    counts = np.nansum(np.ma.filled(top.collections[0].get_array(), np.nan))
    outside = int(fig.get_suptitle().split(", ")[1].split(" outside")[0].replace(",", "")) \
        if "outside" in fig.get_suptitle() else 0
    assert counts + outside == len(depth)  # every estimate is counted once in the top view
    assert (ax.elev, ax.azim) == (15.0, -75.0)  # behind the camera's left shoulder
    turned = cloud_figure(rec, depth, META, view=(40.0, -30.0)).axes[0]
    assert (turned.elev, turned.azim) == (40.0, -30.0)
    with pytest.raises(DataError, match="poses"):
        cloud_figure(scene(poses=False)[0], depth, META)


def test_ray_medians_gather_the_estimates_of_a_ray_on_their_median():
    ray = np.array([0.1, -0.05, 1.0])
    pts = np.vstack([ray * z for z in (1.0, 2.0, 9.0)] + [ray * 4.0 + [5.0, 0, 0]])  # three on one ray, one apart
    cells, counts, spread = ray_medians(pts, angle=0.02, least=1)
    assert sorted(counts.tolist()) == [1, 3]
    on_ray = cells[counts == 3][0]
    assert on_ray[2] == 2.0  # the median depth, not the mean (4)
    assert on_ray[:2] / on_ray[2] == pytest.approx([0.11, -0.05], abs=0.01)  # the cell's central ray
    q25, q75 = np.percentile([1.0, 2.0, 9.0], [25, 75])
    assert spread[counts == 3][0] == pytest.approx((q75 - q25) / 2.0) and spread[counts == 1][0] == 0.0
    assert len(ray_medians(pts, angle=0.02, least=2)[0]) == 1  # a lone estimate is no surface
    near_zero = np.array([[0.1, 0.0, 1e-9], [0.0, 0.0, 1.0]])  # a ray far outside the view: no huge image
    assert len(ray_medians(near_zero, angle=0.01, least=1)[0]) == 2


def test_depth_lattice_finds_the_counter_step_only_where_there_is_one():
    rng = np.random.default_rng(1)
    q = 0.1095123
    steps = rng.integers(3, 60, 5000)
    assert depth_lattice((steps * q).astype(np.float32)) == pytest.approx(q, rel=1e-5)
    assert depth_lattice(rng.uniform(0.3, 6.0, 5000)) is None  # continuous depths
    mixed = np.concatenate([steps * q, rng.uniform(0.3, 6.0, 200)])  # 4 % off the lattice
    assert depth_lattice(mixed) is None
    assert depth_lattice(np.array([0.5, 0.5])) is None  # one value: no step to see


def test_histogram_bins_hold_whole_counter_steps_and_none_is_empty():
    rng = np.random.default_rng(2)
    q = 0.1095123
    z = rng.integers(3, 40, 20_000) * q
    edges, step, per_bin = histogram_edges(z, z, 100)
    assert step == pytest.approx(q) and per_bin >= 1
    assert (edges / q - 0.5) / per_bin == pytest.approx(np.arange(len(edges)))  # edges half a step off the lattice
    counts, _ = np.histogram(z, edges)
    used = counts[np.flatnonzero(counts)[0]:np.flatnonzero(counts)[-1] + 1]
    assert (used > 0).all()
    round_edges = np.arange(0.0, edges[-1], 0.1)  # what a round width did: empty bins between the steps
    round_counts, _ = np.histogram(z, round_edges)
    assert (round_counts[4:40] == 0).any()


def test_histogram_figure_bins_the_networks_depths_on_its_counter_steps():
    rec, depth = scene()
    q = 0.05
    depth["z"] = np.maximum(np.round(depth["z"] / q), 1) * q
    ax = histogram_figure(rec, depth, META).axes[0]
    bars = ax.containers[0]
    lefts = np.array([bar.get_x() for bar in bars])
    widths = np.array([bar.get_width() for bar in bars])
    per_bin = int(round(widths[0] / q))
    assert (lefts / q - 0.5) / per_bin == pytest.approx(np.arange(len(lefts)))
    assert f"({per_bin} counter step" in ax.get_ylabel()
    assert any("n a whole number" in text.get_text() for text in ax.texts)  # the figure says why
    assert "multiples of 0.05 m" in ax.get_legend().get_texts()[0].get_text()


def test_the_velocity_and_position_lines_of_each_axis_look_different():
    rec, depth = scene()
    position, velocity = error_figure(rec, depth, META).axes[:2]
    for ax in (position, velocity):
        lines = [line for line in ax.get_lines() if line.get_label() in ("x", "y", "z", "$t_x$", "$t_y$", "$t_z$")]
        assert len(lines) == 3
        looks = {(line.get_linestyle(), line.get_marker(), line.get_color()) for line in lines}
        assert len({look[0] for look in looks}) == 3 and len({look[1] for look in looks}) >= 2
        y_line, z_line = lines[1], lines[2]
        assert y_line.get_markevery() != z_line.get_markevery()  # markers never sit on each other


def test_the_error_band_window_comes_from_the_data():
    assert band_window_s(108_000, 0.5, 0.001) == pytest.approx(0.005)  # 100 windows, ~1000 estimates each
    assert band_window_s(19_000, 0.5, 0.001) == pytest.approx(0.01)  # 5.3 ms for 200 each, rounded up
    assert band_window_s(2_000, 0.4, 0.001) == pytest.approx(0.05)  # ~250 per window
    assert band_window_s(10**8, 0.5, 0.001) == pytest.approx(0.005)  # at most 100 windows
    assert band_window_s(10**8, 0.05, 0.001) == pytest.approx(0.001)  # at least one step
    assert band_window_s(500, 1.0, 0.004) == pytest.approx(0.4)  # whole steps of 4 ms
    rec, depth = scene()
    error = error_figure(rec, depth, META).axes[2]
    median = next(line for line in error.get_lines() if line.get_label() == "median")
    assert np.diff(median.get_xdata()) == pytest.approx(0.05)  # 9 points over 0.4 s, not 5
    assert np.isfinite(median.get_ydata()).sum() >= 8
    assert "per 50 ms window" in error.get_title()


def test_window_quartiles_per_window_and_thin_windows_left_out():
    t = np.array([0, 10, 20, 30, 100, 110, 250])
    v = np.array([1.0, 2.0, 3.0, 4.0, 10.0, 20.0, 7.0])
    q, counts = window_quartiles(t, v, 100, 3, least=2)
    assert counts.tolist() == [4, 2, 1]
    assert q[:, 0] == pytest.approx(np.percentile([1, 2, 3, 4], [25, 50, 75]))
    assert q[1, 1] == 15.0 and np.isnan(q[:, 2]).all()


@pytest.mark.parametrize("kind, make", [("depthmap", depth_map_figure), ("histogram", histogram_figure),
                                        ("error", error_figure), ("cloud", cloud_figure)])
def test_each_figure_saves_a_png_of_its_size(tmp_path, kind, make):
    rec, depth = scene()
    path = save_figure(make(rec, depth, META), tmp_path / f"{kind}.png")
    assert path.stat().st_size > 10_000
    assert png_size(path) == expected_pixels(kind)


def test_plot_all_writes_what_the_recording_supports(tmp_path):
    rec, depth = scene()
    paths = plot_all(rec, depth, META, tmp_path, prefix="run_")
    assert [p.name for p in paths] == ["run_depthmap.png", "run_histogram.png", "run_error.png", "run_cloud.png"]
    assert all(p.stat().st_size > 0 for p in paths)
    bare, _ = scene(gt=False, poses=False)
    assert [p.name for p in plot_all(bare, depth, META, tmp_path / "bare")] == ["depthmap.png", "histogram.png"]
    assert png_size(tmp_path / "bare" / "depthmap.png") == expected_pixels("depthmap_single")


def write_inputs(folder: Path, gt: bool = True) -> tuple[str, str]:
    rec, depth = scene(n=1500, gt=gt)
    traj = rec.trajectory
    write_ecd(folder / "rec", rec.events, intrinsics=rec.intrinsics, sensor_size=SIZE, gt_depth=rec.gt_depth,
              times=traj.times, positions=traj.positions, quaternions=traj.quaternions)
    write_depth(folder / "depth.npz", depth, **META)
    return str(folder / "rec"), str(folder / "depth.npz")


def test_cli_plot_writes_the_files_it_prints(tmp_path, capsys):
    rec, dep = write_inputs(tmp_path)
    out = tmp_path / "figs" / "map.png"
    assert main(["plot", "depthmap", rec, dep, "--out", str(out), "--window", "0.1:0.2", "--reduce", "median"]) == 0
    assert capsys.readouterr().out.split() == [str(out)]
    assert png_size(out) == expected_pixels("depthmap")
    assert main(["plot", "all", rec, dep, "--no-gt", "--window", "50ms"]) == 0
    printed = capsys.readouterr().out.split()
    assert [Path(p).name for p in printed] == ["depth_depthmap.png", "depth_histogram.png", "depth_error.png",
                                               "depth_cloud.png"]
    assert all(Path(p).is_file() for p in printed)


def test_cli_plot_explains_what_a_figure_needs(tmp_path, capsys):
    rec, dep = write_inputs(tmp_path, gt=False)
    assert main(["plot", "error", rec, dep]) == 2
    assert "events_depth.npy" in capsys.readouterr().err
    assert main(["plot", "histogram", rec, dep, "--out", str(tmp_path / "h.jpg")]) == 2
    assert "PNG" in capsys.readouterr().err


class Sliding:
    """A trajectory with positions but no rotations, like the simulator's (camera = world axes)."""

    def position_at(self, t):
        t = np.atleast_1d(t)
        return np.column_stack([0.5 * t, 0 * t, 0 * t])

    def velocity_at(self, t):
        return np.tile([0.5, 0.0, 0.0], (len(np.atleast_1d(t)), 1))


def test_a_trajectory_with_positions_only_places_points_and_draws_the_path():
    depth = np.zeros(1, DEPTH_DTYPE)
    depth["x"], depth["y"], depth["z"], depth["t"] = 20, 15, 2.0, 200_000
    assert world_points(depth, Intrinsics(30.0, 30.0, 20.0, 15.0), Sliding()) == pytest.approx(
        np.array([[0.1, 0.0, 2.0]]))
    rec, depth = scene()
    rec.trajectory = Sliding()
    position = error_figure(rec, depth, META).axes[0]
    assert position.get_ylabel() == "position (world) [m]"
    assert position.get_lines()[0].get_ydata()[-1] == pytest.approx(0.5 * 0.402, abs=1e-3)
    path = next(line for line in cloud_figure(rec, depth, META).axes[0].get_lines()
                if line.get_label() == "camera path")
    assert path.get_data_3d()[0][-1] == pytest.approx(0.5 * 0.402, abs=1e-3)  # 0.5 m/s to the right


def test_figures_of_a_run_without_estimates_still_render(tmp_path):
    rec, depth = scene(n=500)
    paths = plot_all(rec, depth[:0], META, tmp_path)
    assert len(paths) == 4 and all(p.stat().st_size > 0 for p in paths)


def test_cli_error_window_is_auto_or_a_positive_duration(tmp_path, capsys):
    rec, dep = write_inputs(tmp_path)
    assert main(["plot", "error", rec, dep, "--out", str(tmp_path / "e.png"), "--error-window", "20ms"]) == 0
    assert png_size(tmp_path / "e.png") == expected_pixels("error")
    capsys.readouterr()
    assert main(["plot", "error", rec, dep, "--out", str(tmp_path / "f.png"), "--error-window", "0"]) == 2
    assert "'auto'" in capsys.readouterr().err


def test_the_cloud_says_what_it_lacks_and_only_that():
    from tofnet.eval.plots import available_kinds
    from tofnet.events import make_events
    from tofnet.io.recording import Intrinsics, Recording

    events = make_events([0, 1000], [1, 2], [1, 1], [1, 0])
    with_camera = Recording(events, intrinsics=Intrinsics(200.0, 200.0, 120.0, 90.0))
    assert available_kinds(with_camera)["cloud"] == "needs camera poses (groundtruth.txt); the recording has none"
    assert "intrinsics" in available_kinds(Recording(events))["cloud"]
