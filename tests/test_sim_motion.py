"""Random scenes under general motion (``tofnet.sim.motion``)."""

from __future__ import annotations

import numpy as np
import pytest

from tofnet.sim import SimError, generate, scenario
from tofnet.sim.motion import MOTIONS, NOISE_RANGE, OBJECT_DEPTHS, SPEED_RANGE, WALL_DEPTHS, random_motion


@pytest.mark.parametrize("motion", MOTIONS)
def test_a_variant_is_reproducible_and_variants_differ(motion):
    assert random_motion(motion, 3, 0.5) == random_motion(motion, 3, 0.5)
    assert random_motion(motion, 3, 0.5).scene != random_motion(motion, 4, 0.5).scene
    assert scenario(f"random_{motion}:3", 0.5) == random_motion(motion, 3, 0.5)
    assert scenario(f"random_{motion}", 0.5) == random_motion(motion, 0, 0.5)


@pytest.mark.parametrize("variant", range(6))
@pytest.mark.parametrize("motion", MOTIONS)
def test_scenes_speeds_and_noise_stay_in_their_ranges(motion, variant):
    config = random_motion(motion, variant, 1.0)
    depths = [o.center[2] for o in config.scene.objects]
    assert 4 <= len(depths) <= 8 and all(OBJECT_DEPTHS[0] <= z <= OBJECT_DEPTHS[1] for z in depths)
    assert WALL_DEPTHS[0] <= config.scene.background_depth <= WALL_DEPTHS[1]
    assert NOISE_RANGE[0] <= config.noise_rate <= NOISE_RANGE[1]
    t = np.linspace(0, 0.999, 1000)
    velocity = config.trajectory.velocity_at(t)
    rms = float(np.sqrt(np.mean(np.sum(velocity ** 2, axis=1))))
    assert SPEED_RANGE[0] * 0.99 <= rms <= SPEED_RANGE[1] * (1.05 if motion == "forward" else 1.01)
    if motion == "steady":
        assert np.ptp(velocity, axis=0).max() == 0
    elif motion == "forward":
        assert np.all(velocity[:, 2] > 0) and np.mean(np.abs(velocity[:, 2])) > np.mean(np.abs(velocity[:, 0]))
    else:  # the dominant axis reverses every 100-300 ms or so: 2-12 sign changes in 1 s
        changes = np.count_nonzero(np.diff(np.sign(velocity[:, 0])) != 0)
        assert 2 <= changes <= 12


@pytest.mark.parametrize("variant", range(4))
def test_shake_turns_no_faster_than_the_translation_moves_the_image(variant):
    config = random_motion("shake", variant, 1.0)
    assert config.imu is not None and getattr(config.trajectory, "rotates", False)
    median_depth = float(np.median([o.center[2] for o in config.scene.objects]))
    t = np.linspace(0, 0.999, 1000)
    rms_speed = float(np.sqrt(np.mean(np.sum(config.trajectory.world_velocity_at(t) ** 2, axis=1))))
    omega = np.linalg.norm(config.trajectory.angular_velocity_at(t), axis=1)
    assert 0 < omega.max() <= 1.6 * rms_speed / median_depth


def test_a_short_run_simulates_with_noise_and_the_scene_in_depth():
    config = scenario("random_reversing:2", 0.2).replace(sensor_size=(96, 72))
    result = generate(config, seed=2)
    depth = result.gt_depth[np.isfinite(result.gt_depth)]
    assert result.stats["contrast_events"] > 1000 and result.stats["noise_events"] > 0
    assert OBJECT_DEPTHS[0] * 0.8 < depth.min() and depth.max() < WALL_DEPTHS[1] * 1.5


@pytest.mark.parametrize("name", ["random_shake:x", "random_shake:-1", "random_nothing:1", "slider:2"])
def test_bad_variants_are_one_line_errors(name):
    with pytest.raises(SimError, match="scenario"):
        scenario(name)
