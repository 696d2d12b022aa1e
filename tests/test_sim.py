"""The simulator's physics: edge speed and polarity, depth per event, render spacing, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tofnet.errors import TofnetError
from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Intrinsics
from tofnet.sim import Plane, Scene, Segment, SimConfig, SimError, Texture, Trajectory, constant, generate, scenario
from tofnet.sim.dvs import count_crossings, emit_crossings
from tofnet.sim.render import flow_bound, render_times

K = Intrinsics(fx=100.0, fy=100.0, cx=31.5, cy=7.5)
SIZE = (64, 16)


def edge_config(z: float = 1.0, v: float = 0.5, levels=(0.2, 0.8), sigma: float = 0.03, duration: float = 0.8,
                start_x: float = -0.2) -> SimConfig:
    """A fronto-parallel plane at depth ``z`` with one vertical edge at world x = 0, dark on the left."""
    plane = Plane(center=(0.0, 0.0, z), size=(4.0, 2.0), texture=Texture("edge", levels=levels, angle=0.0))
    return SimConfig("edge", Scene((plane,), background_depth=z + 2.0), constant((v, 0.0, 0.0), duration,
                     start=(start_x, 0.0, 0.0)), duration, intrinsics=K, sensor_size=SIZE, contrast_sigma=sigma)


def first_event_times(events: np.ndarray, width: int) -> np.ndarray:
    """Per column, the median over rows of each pixel's first event time (s); NaN without events."""
    out = np.full(width, np.nan)
    for u in range(width):
        sel = events[events["x"] == u]
        if sel.size:
            firsts = [sel["t"][sel["y"] == y].min() for y in np.unique(sel["y"])]
            out[u] = np.median(firsts) * 1e-6
    return out


@pytest.mark.parametrize("z, v", [(1.0, 0.5), (0.6, 0.3)])
def test_edge_crossing_times_advance_at_f_v_over_z(z, v):
    result = generate(edge_config(z=z, v=v), seed=3)
    expected = K.fx * v / z  # px/s; the image moves to -u while the camera moves to +x
    times = first_event_times(result.events, SIZE[0])
    # Columns the edge fully crosses during the run, away from where it starts and ends.
    start_u = K.cx + K.fx * 0.2 / z
    end_u = start_u - expected * 0.8
    cols = np.arange(SIZE[0])
    sel = (cols > max(end_u, 0) + 3) & (cols < min(start_u, SIZE[0]) - 3) & np.isfinite(times)
    assert sel.sum() >= 10
    slope = np.polyfit(cols[sel], times[sel], 1)[0]  # s/px, negative: later to the left
    assert -1 / slope == pytest.approx(expected, rel=0.03)


def test_polarity_follows_the_edge_contrast():
    dark_to_bright = generate(edge_config(levels=(0.2, 0.8), duration=0.3), seed=0).events
    bright_to_dark = generate(edge_config(levels=(0.8, 0.2), duration=0.3), seed=0).events
    assert dark_to_bright.size > 100 and bright_to_dark.size > 100
    # The edge moves left, so pixels left of it (low side) brighten: ON; reversed levels: OFF.
    assert np.all(dark_to_bright["p"] == 1)
    assert np.all(bright_to_dark["p"] == 0)
    # About log(0.8/0.2)/0.2 ~ 7 events per pixel the edge crosses.
    per_pixel = np.bincount(dark_to_bright["x"].astype(int) + SIZE[0] * dark_to_bright["y"])
    assert 5 <= np.median(per_pixel[per_pixel > 0]) <= 9


def test_ground_truth_depth_is_the_plane_depth():
    result = generate(edge_config(z=1.3, duration=0.3), seed=1)
    assert result.gt_depth.shape == result.events.shape
    np.testing.assert_allclose(result.gt_depth, 1.3, rtol=1e-6)


def test_ground_truth_depth_follows_forward_motion():
    plane = Plane(center=(0.0, 0.0, 1.0), size=(3.0, 2.0), texture=Texture("shapes", scale=0.02))
    config = SimConfig("approach", Scene((plane,), background_depth=4.0),
                       constant((0.0, 0.0, 1.0), 0.2, start=(0.0, 0.0, 0.0)), 0.2, intrinsics=K, sensor_size=SIZE)
    result = generate(config, seed=0)
    assert result.events.size > 500
    expected = 1.0 - 1.0 * result.events["t"] * 1e-6
    # Linear in time between renders, and events are stamped to the rounded microsecond.
    np.testing.assert_allclose(result.gt_depth, expected, rtol=1e-5)


def test_events_are_sorted_typed_and_inside_the_sensor():
    result = generate(scenario("all_axes", 0.03).replace(sensor_size=(48, 36)), seed=0)
    ev = result.events
    assert ev.dtype == EVENT_DTYPE
    assert np.all(np.diff(ev["t"]) >= 0)
    assert ev["x"].max() < 48 and ev["y"].max() < 36
    assert 0 <= ev["t"].min() and ev["t"].max() <= 30_000
    assert set(np.unique(ev["p"])) == {0, 1}
    assert np.all(np.isfinite(result.gt_depth)) and result.gt_depth.min() > 0.2


def test_same_seed_same_events_other_seed_other_events():
    config = scenario("diagonal", 0.02).replace(sensor_size=(48, 36))
    a, b = generate(config, seed=7), generate(config, seed=7)
    assert np.array_equal(a.events, b.events)
    assert np.array_equal(a.gt_depth, b.gt_depth)
    c = generate(config, seed=8)
    assert not (a.events.size == c.events.size and np.array_equal(a.events, c.events))


@pytest.mark.parametrize("name", ["slider", "fast_slider", "all_axes", "forward"])
def test_renders_move_the_image_at_most_a_quarter_pixel(name):
    config = scenario(name, 0.02).replace(sensor_size=(48, 36))
    result = generate(config, seed=0)
    assert 0 < result.stats["max_render_step_px"] <= 0.25


def test_render_times_bound_every_interval():
    # Two segments with different speeds; the boundary is a render time.
    traj = Trajectory((0.0, 0.0, 0.0), (Segment(0.1, (0.5, 0.0, 0.0)), Segment(0.1, (0.0, -1.0, 0.2))))
    times = render_times(traj, 0.2, 1.0, K, SIZE)
    assert times[0] == 0 and times[-1] == pytest.approx(0.2) and np.any(np.isclose(times, 0.1))
    for t0, t1 in zip(times[:-1], times[1:]):
        vel = traj.velocity_at(0.5 * (t0 + t1))[0]
        z_near = 1.0 - traj.position_at(t1)[0, 2]
        assert (t1 - t0) * flow_bound(vel, z_near, K, SIZE) <= 0.25 + 1e-9
    # Pure x motion: the bound is f*v/z exactly.
    assert flow_bound(np.array([0.5, 0, 0]), 2.0, K, SIZE) == pytest.approx(100 * 0.5 / 2.0)


def test_several_crossings_between_two_renders_are_spread_in_time():
    l0, l1 = np.array([0.0, 0.0, 0.0]), np.array([0.65, -0.45, 0.1])
    ref = np.zeros(3)
    c = np.full(3, 0.2)
    d0, d1 = np.array([1.0, 2.0, 1.0]), np.array([1.03, 2.2, 1.0])
    n = count_crossings(l0, l1, ref, c, c)
    assert n == 3 + 2  # 0.65 -> 3 ON, -0.45 -> 2 OFF, 0.1 -> none
    out = [np.zeros(8, dtype=dt) for dt in (np.int64, np.uint16, np.uint16, np.uint8, np.float32)]
    assert emit_crossings(l0, l1, d0, d1, ref, c, c, 1000.0, 2000.0, 3, 0.05, False, *out, 0) == n
    t, x, _, p, d = (o[:n] for o in out)
    np.testing.assert_array_equal(x, [0, 0, 0, 1, 1])
    np.testing.assert_array_equal(p, [1, 1, 1, 0, 0])
    np.testing.assert_allclose(t[:3], 1000 + 1000 * np.array([0.2, 0.4, 0.6]) / 0.65, atol=0.5)
    np.testing.assert_allclose(t[3:], 1000 + 1000 * np.array([0.2, 0.4]) / 0.45, atol=0.5)
    # Depth interpolated to the event time (the 10 % jump at pixel 1 takes the nearer render).
    np.testing.assert_allclose(d[:3], 1.0 + 0.03 * np.array([0.2, 0.4, 0.6]) / 0.65, rtol=1e-6)
    np.testing.assert_allclose(d[3:], [2.0, 2.2])
    np.testing.assert_allclose(ref, [0.6, -0.4, 0.0])


def test_background_noise_events_have_depth():
    config = edge_config(duration=0.2).replace(noise_rate=20.0)
    result = generate(config, seed=2)
    expected = 20.0 * SIZE[0] * SIZE[1] * 0.2
    assert abs(result.stats["noise_events"] - expected) < 5 * math.sqrt(expected)
    assert np.all(np.isclose(result.gt_depth, 1.0, rtol=1e-6) | np.isclose(result.gt_depth, 3.0, rtol=1e-6))


def test_camera_running_into_an_object_is_an_error():
    config = edge_config(z=0.5).replace(trajectory=constant((0.0, 0.0, 1.0), 0.8, start=(0.0, 0.0, 0.0)))
    with pytest.raises(SimError, match="trajectory: .*in front of every object"):
        generate(config)


def test_bad_parameters_name_the_field():
    with pytest.raises(TofnetError, match="texture kind"):
        Texture("plaid")
    with pytest.raises(TofnetError, match="contrast_on"):
        edge_config().replace(contrast_on=0.0)
    with pytest.raises(TofnetError, match="segment 0 duration"):
        Trajectory((0, 0, 0), (Segment(-1.0, (0, 0, 0)),))
    with pytest.raises(TofnetError, match="slider"):
        scenario("sliderr")


def test_occluding_contours_can_be_labelled_with_the_nearer_surface():
    config = scenario("slider", 0.05).replace(sensor_size=(60, 45))
    in_time = generate(config)
    nearer = generate(config.replace(occlusion_depth="nearer_surface"))
    assert np.array_equal(in_time.events, nearer.events)
    relabelled = in_time.gt_depth != nearer.gt_depth
    assert relabelled.any() and np.all(nearer.gt_depth[relabelled] < in_time.gt_depth[relabelled])
    with pytest.raises(SimError, match="occlusion_depth: expected one of"):
        config.replace(occlusion_depth="farther")


def test_the_simulator_modules_import_one_another_without_a_cycle():
    """The two engines share their common part from below (``sim/result.py``), so no module of
    ``tofnet.sim`` reaches itself through imports, at module level or inside a function."""
    import ast
    from pathlib import Path

    import tofnet.sim
    root = Path(tofnet.sim.__file__).parent
    graph = {}
    for path in root.glob("*.py"):
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("tofnet.sim."):
                names.add(node.module.split(".")[2])
            elif isinstance(node, ast.Import):
                names.update(a.name.split(".")[2] for a in node.names if a.name.startswith("tofnet.sim."))
        graph[path.stem] = names
    assert "engine_rotating" in graph["engine"]  # the graph is read (a lazy import counts too)

    def reaches(start: str) -> set[str]:
        seen, todo = set(), list(graph.get(start, ()))
        while todo:
            name = todo.pop()
            if name not in seen:
                seen.add(name)
                todo.extend(graph.get(name, ()))
        return seen

    assert [name for name in sorted(graph) if name in reaches(name)] == []
