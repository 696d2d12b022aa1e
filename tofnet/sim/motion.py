"""Random scenes under general motion: the hard cases for depth from event timing.

Each ``random_*`` scenario draws, from its variant number, a scene of 4-8 textured boxes
and boards 0.6-4.3 m away in front of a textured wall 5-10 m away, background activity
of 0.5-5 Hz per pixel (log-uniform) and the default pixels' threshold mismatch, and a
camera motion of one class:

- ``steady``: one constant velocity of 0.2-1 m/s in a random direction (mostly sideways);
- ``reversing``: smooth random 3-D translation whose axes reverse every 100-300 ms;
- ``forward``: mostly along the optical axis (0.2-1 m/s) with a reversing sideways sway;
- ``shake``: ``reversing`` held by a hand that turns the camera as well, its rotational
  image motion up to the translational one at the scene's median depth (IMU included).

An event at an occluding contour gets the nearer surface's depth (``occlusion_depth``): its
timing is that surface's motion, so that is the depth an estimator should find.

Velocities are piecewise constant over ``STEP_S`` (2 ms), fine enough that the motion is
smooth to the network (1 ms steps, poses at 1 kHz). Variants are reproducible: the same
name and variant give the same ``SimConfig`` everywhere. docs/simulator.md lists them;
docs/time_surface.md uses them with variants kept apart for tuning and for testing.
"""

from __future__ import annotations

import math

import numpy as np

from tofnet.sim.camera import DEFAULT_INTRINSICS, Segment, Trajectory
from tofnet.sim.config import SimConfig
from tofnet.sim.errors import SimError
from tofnet.sim.rotation import ImuModel, RotatingTrajectory, Sway
from tofnet.sim.scene import Box, Plane, Scene
from tofnet.sim.texture import Texture

#: Motion classes, in the order of the docs' tables.
MOTIONS = ("steady", "reversing", "forward", "shake")
#: Length of each piece of constant velocity, seconds.
STEP_S = 0.002
#: Translational speed range (m/s, RMS over the run for the reversing classes).
SPEED_RANGE = (0.2, 1.0)
#: Half-periods of the reversing motions, seconds (one reversal per half-period).
REVERSAL_RANGE = (0.1, 0.3)
#: Background activity range, events per pixel per second (drawn log-uniform).
NOISE_RANGE = (0.5, 5.0)
#: Depth ranges of the objects and of the wall behind them, metres.
OBJECT_DEPTHS, WALL_DEPTHS = (0.6, 4.3), (5.0, 10.0)


def random_scene(rng: np.random.Generator) -> Scene:
    """4-8 boxes and boards at ``OBJECT_DEPTHS`` spread over the view, a wall at ``WALL_DEPTHS``.

    Texture features are drawn 8-20 px across at each surface's depth (DAVIS240-like optics).
    """
    focal = DEFAULT_INTRINSICS.fx
    kinds = ("shapes", "checker", "stripes")
    objects = []
    for i in range(int(rng.integers(4, 9))):
        z = float(rng.uniform(*OBJECT_DEPTHS))
        x, y = (float(v) for v in rng.uniform([-0.45 * z, -0.35 * z], [0.45 * z, 0.35 * z]))
        width = float(rng.uniform(0.12, 0.35)) * z
        feature = float(rng.uniform(8, 20)) * z / focal
        texture = Texture(str(rng.choice(kinds)), scale=feature)
        if rng.random() < 0.5:
            objects.append(Box(center=(x, y, z), size=(width, float(rng.uniform(0.6, 1.4)) * width, 0.6 * width),
                               yaw=float(rng.uniform(-0.6, 0.6)), texture=texture, name=f"box {i}"))
        else:
            objects.append(Plane(center=(x, y, z), size=(width, float(rng.uniform(0.5, 1.2)) * width),
                                 yaw=float(rng.uniform(-0.7, 0.7)), pitch=float(rng.uniform(-0.4, 0.4)),
                                 texture=texture, name=f"board {i}"))
    wall = float(rng.uniform(*WALL_DEPTHS))
    return Scene(objects=tuple(objects), background_depth=wall,
                 background=Texture("shapes", scale=float(rng.uniform(10, 20)) * wall / focal))


def _reversing_profile(rng: np.random.Generator, t: np.ndarray, half_period: float) -> np.ndarray:
    """A smooth zero-mean signal of unit RMS whose sign changes about every ``half_period`` s."""
    base = 1.0 / (2.0 * half_period)
    signal = np.zeros_like(t)
    for frequency in base * rng.uniform(0.8, 1.25, size=3):
        signal += rng.uniform(0.5, 1.0) * np.sin(2 * math.pi * frequency * t + rng.uniform(0, 2 * math.pi))
    return signal / max(float(np.sqrt(np.mean(signal ** 2))), 1e-12)


def _unit(rng: np.random.Generator, weights: tuple[float, float, float]) -> np.ndarray:
    v = rng.normal(size=3) * np.asarray(weights)
    return v / np.linalg.norm(v)


def random_velocity(motion: str, rng: np.random.Generator, duration: float) -> np.ndarray:
    """Camera velocity (m/s, world frame) per ``STEP_S`` piece, shape ``(n, 3)``, for a motion class."""
    n = max(1, int(math.ceil(duration / STEP_S - 1e-9)))
    t = (np.arange(n) + 0.5) * STEP_S
    speed = float(rng.uniform(*SPEED_RANGE))
    if motion == "steady":
        return np.tile(speed * _unit(rng, (1.0, 0.7, 0.25)), (n, 1))
    half = float(rng.uniform(*REVERSAL_RANGE))
    if motion == "forward":
        sway = np.column_stack([_reversing_profile(rng, t, half), _reversing_profile(rng, t, half), np.zeros(n)])
        return speed * (np.array([0.0, 0.0, 1.0]) + 0.3 * sway)
    axes = (1.0, 0.8, 0.4)  # reversing, shake: mostly sideways, some z
    profiles = np.column_stack([w * _reversing_profile(rng, t, half * rng.uniform(0.8, 1.25)) for w in axes])
    return speed * profiles / math.sqrt(sum(w * w for w in axes))


def _trajectory(velocity: np.ndarray) -> Trajectory:
    # Start where the camera's mean position is the origin, so the scene stays in view.
    positions = np.cumsum(velocity, axis=0) * STEP_S
    start = -positions.mean(axis=0)
    return Trajectory(start=tuple(float(v) for v in start),
                      segments=tuple(Segment(STEP_S, tuple(float(c) for c in v)) for v in velocity))


def _hand_sway(rng: np.random.Generator, peak_rate: float) -> Sway:
    waves = []
    for _ in range(2):
        frequency = float(rng.uniform(1.5, 5.0))
        waves.append((peak_rate / 2 / (2 * math.pi * frequency), frequency, float(rng.uniform(0, 2 * math.pi))))
    return Sway(waves=tuple(waves))


def random_motion(motion: str, variant: int = 0, duration: float = 1.0) -> SimConfig:
    """The ``random_<motion>`` scenario number ``variant`` (any int >= 0), ``duration`` seconds."""
    if motion not in MOTIONS:
        raise SimError(f"motion: expected one of {', '.join(MOTIONS)}, got {motion!r}")
    if not (isinstance(variant, int) and variant >= 0):
        raise SimError(f"variant: expected an integer >= 0, got {variant!r}")
    rng = np.random.default_rng([variant, MOTIONS.index(motion), 7919])
    scene = random_scene(rng)
    velocity = random_velocity(motion, rng, duration)
    trajectory: Trajectory | RotatingTrajectory = _trajectory(velocity)
    imu = None
    if motion == "shake":
        # Rotational image motion f*ω up to the translational f*|v|/Z at the objects' median depth.
        median_depth = float(np.median([o.center[2] for o in scene.objects]))
        rms_speed = float(np.sqrt(np.mean(np.sum(velocity ** 2, axis=1))))
        peak = float(rng.uniform(0.3, 1.0)) * rms_speed / median_depth
        trajectory = RotatingTrajectory(trajectory, yaw=_hand_sway(rng, peak), pitch=_hand_sway(rng, peak),
                                        roll=_hand_sway(rng, 0.5 * peak))
        imu = ImuModel()
    noise = float(math.exp(rng.uniform(math.log(NOISE_RANGE[0]), math.log(NOISE_RANGE[1]))))
    # An event at an occluding contour is made by the nearer surface's motion: that is the depth to find.
    return SimConfig(f"random_{motion}:{variant}", scene, trajectory, duration, noise_rate=noise, imu=imu,
                     occlusion_depth="nearer_surface",
                     description=f"random scene, {motion} motion (variant {variant}), noise {noise:.1f} Hz/px")


def _scenario(motion: str):
    def make(duration: float = 1.0, variant: int = 0) -> SimConfig:
        return random_motion(motion, variant, duration)
    make.__name__ = f"random_{motion}"
    return make


#: ``random_<motion>`` -> ``f(duration, variant=0) -> SimConfig``; ``scenario("random_shake:3")`` picks a variant.
MOTION_SCENARIOS = {f"random_{motion}": _scenario(motion) for motion in MOTIONS}
