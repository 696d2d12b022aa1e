"""Built-in scenarios: the paper's synthetic sequences, made here instead of with eSim.

``SCENARIOS`` maps a name to a function ``(duration) -> SimConfig``; trajectories
with direction changes scale their segments with ``duration``. Objects sit 0.3-3 m
from the camera, so at 1 ms steps an edge takes well under 255 steps (8-bit
counters) to cross a pixel wherever the image moves by more than ~4 px/s.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from tofnet.sim.camera import Segment, Trajectory, constant
from tofnet.sim.config import SimConfig
from tofnet.sim.errors import SimError
from tofnet.sim.scene import Box, Plane, Scene
from tofnet.sim.texture import Texture


def desk_scene() -> Scene:
    """Objects at 0.35-3 m in front of the origin, spread over x and y (like ECD ``slider_depth``)."""
    return Scene(objects=(
        Plane(center=(-0.04, -0.03, 0.35), size=(0.09, 0.07), name="card",
              texture=Texture("checker", scale=0.012, angle=math.radians(30))),
        Box(center=(-0.22, 0.06, 0.6), size=(0.12, 0.16, 0.12), name="small box",
            texture=Texture("shapes", scale=0.025)),
        Box(center=(0.2, -0.06, 0.95), size=(0.2, 0.24, 0.2), yaw=math.radians(25), name="box",
            texture=Texture("checker", scale=0.035)),
        Plane(center=(-0.15, -0.3, 1.3), size=(0.5, 0.3), pitch=math.radians(-35), name="tilted board",
              texture=Texture("shapes", scale=0.05)),
        Box(center=(0.6, 0.1, 1.7), size=(0.4, 0.5, 0.35), name="big box",
            texture=Texture("shapes", scale=0.06)),
        Plane(center=(-0.85, 0.0, 2.0), size=(1.2, 1.2), yaw=math.radians(55), name="side wall",
              texture=Texture("stripes", scale=0.06, angle=math.radians(70))),
        Plane(center=(0.0, 0.42, 1.8), size=(3.5, 2.4), pitch=math.radians(90), name="floor",
              texture=Texture("shapes", scale=0.1)),
    ), background_depth=3.0, background=Texture("shapes", scale=0.35))


def corridor_scene() -> Scene:
    """Walls, floor and boxes from 1 m on, off the optical axis, for motion along z."""
    return Scene(objects=(
        Plane(center=(0.55, 0.0, 2.2), size=(2.4, 1.0), yaw=math.radians(90), name="right wall",
              texture=Texture("shapes", scale=0.07)),
        Plane(center=(-0.55, 0.0, 2.2), size=(2.4, 1.0), yaw=math.radians(90), name="left wall",
              texture=Texture("checker", scale=0.08)),
        Plane(center=(0.0, 0.4, 2.2), size=(1.1, 2.4), pitch=math.radians(90), name="floor",
              texture=Texture("shapes", scale=0.08)),
        Box(center=(-0.25, -0.15, 1.2), size=(0.15, 0.15, 0.15), name="near box",
            texture=Texture("shapes", scale=0.025)),
        Box(center=(0.25, 0.2, 1.6), size=(0.2, 0.2, 0.2), yaw=math.radians(30), name="box",
            texture=Texture("checker", scale=0.04)),
        Plane(center=(0.15, -0.2, 2.4), size=(0.4, 0.3), name="poster", texture=Texture("shapes", scale=0.04)),
    ), background_depth=3.4, background=Texture("shapes", scale=0.3))


def slider(duration: float = 1.0) -> SimConfig:
    return SimConfig("slider", desk_scene(), constant((0.55, 0.0, 0.0), duration), duration,
                     description="horizontal slider at 0.55 m/s (paper Table 2, Fig. 4a)")


def fast_slider(duration: float = 1.0) -> SimConfig:
    # Back and forth every 0.25 s so that 2.6 m/s stays within the scene (0.65 m of travel).
    n = max(1, round(duration / 0.25))
    segments = tuple(Segment(duration / n, (2.6 if i % 2 == 0 else -2.6, 0.0, 0.0)) for i in range(n))
    start = (-0.5 * 2.6 * duration / n, 0.0, 0.0)
    return SimConfig("fast_slider", desk_scene(), Trajectory(start, segments), duration,
                     description="horizontal slider at 2.6 m/s, reversing every 0.25 s (paper Fig. 4b)")


def vertical(duration: float = 1.0) -> SimConfig:
    return SimConfig("vertical", desk_scene(), constant((0.0, 0.4, 0.0), duration), duration,
                     description="downwards at 0.4 m/s")


def diagonal(duration: float = 1.0) -> SimConfig:
    return SimConfig("diagonal", desk_scene(), constant((0.4, -0.3, 0.0), duration), duration,
                     description="right and up at 0.5 m/s (0.4, -0.3, 0)")


def all_axes(duration: float = 1.0) -> SimConfig:
    velocities = ((0.5, 0.0, 0.0), (0.0, 0.4, 0.0), (0.0, 0.0, 0.4), (-0.5, 0.0, 0.0), (0.0, -0.4, 0.0),
                  (0.3, 0.2, -0.3))
    segments = tuple(Segment(duration / len(velocities), v) for v in velocities)
    return SimConfig("all_axes", desk_scene(), Trajectory((-0.05, -0.05, 0.0), segments), duration,
                     description="x, y, z and combined, 6 segments with sudden turns (paper Table 1, Fig. 3)")


def forward(duration: float = 1.0) -> SimConfig:
    return SimConfig("forward", corridor_scene(), constant((0.0, 0.0, 0.5), duration, start=(0.0, 0.0, 0.0)),
                     duration, description="forward along z at 0.5 m/s down a corridor")


#: Scenario name -> ``f(duration) -> SimConfig``.
SCENARIOS: dict[str, Callable[[float], SimConfig]] = {
    "slider": slider,
    "fast_slider": fast_slider,
    "vertical": vertical,
    "diagonal": diagonal,
    "all_axes": all_axes,
    "forward": forward,
}


def scenario(name: str, duration: float | None = None) -> SimConfig:
    """The config of a built-in scenario; a ``SimError`` lists the known names."""
    if name not in SCENARIOS:
        raise SimError(f"scenario: unknown name {name!r}; expected one of {', '.join(SCENARIOS)}")
    if duration is not None and not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise SimError(f"duration: expected a positive number of seconds, got {duration!r}")
    return SCENARIOS[name](1.0 if duration is None else float(duration))
