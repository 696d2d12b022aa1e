"""Synthetic event-camera sequences with ground-truth depth, in the spirit of ESIM.

A scene of textured planes and boxes is ray-cast along a piecewise-constant-velocity
trajectory (which may also turn: ``RotatingTrajectory``), densely enough that the image moves at most
0.25 px between renders; each pixel emits events where its log intensity crosses its
contrast thresholds (ESIM's method). See ``docs/simulator.md``.

>>> from tofnet.sim import simulate
>>> summary = simulate("slider", "out/slider", duration=0.2)  # doctest: +SKIP
"""

import tofnet.numba_cache  # noqa: F401 - before the simulator's cached kernels are defined
from tofnet.sim.camera import DEFAULT_INTRINSICS, DEFAULT_SENSOR_SIZE, Segment, Trajectory, constant
from tofnet.sim.config import SimConfig
from tofnet.sim.engine import generate
from tofnet.sim.result import SimResult
from tofnet.sim.errors import SimError
from tofnet.sim.run import resolve, simulate, summarize, write_result
from tofnet.sim.rotation import ImuModel, RotatingTrajectory, Sway
from tofnet.sim.scenarios import ROOM_SCENARIOS, ROTATION_SCENARIOS, SCENARIOS, built_in_scenarios, scenario
from tofnet.sim.scene import Box, Plane, Scene
from tofnet.sim.texture import Texture

__all__ = ["SCENARIOS", "ROOM_SCENARIOS", "ROTATION_SCENARIOS", "RotatingTrajectory", "Sway", "ImuModel", "built_in_scenarios", "scenario", "simulate", "generate", "resolve", "summarize", "write_result", "SimConfig",
           "SimResult", "SimError", "Scene", "Plane", "Box", "Texture", "Trajectory", "Segment", "constant",
           "DEFAULT_INTRINSICS", "DEFAULT_SENSOR_SIZE"]
