"""The conformance cases: small named scenes built in code, each aimed at one part of the semantics.

Every case builds a fresh ``Scene`` (network, recording, compiler patch option) from
the helpers of ``tofnet.testing``. Intrinsics are ``TEST_INTRINSICS`` (f = 200 px,
principal point at 0) unless a case says otherwise; a camera velocity ``t`` makes the
image of a point at depth Z move by ``-f t / Z`` px/s, which is how the cases choose
velocities that give depths inside the default 0.05-20 m range.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from tofnet.core.network import Network
from tofnet.events import EVENT_DTYPE, make_events
from tofnet.io.recording import Intrinsics, Recording
from tofnet.networks import denoised_network, depth_network, improved_network, multi_distance_network
from tofnet.processes import DepthProcess, InputProcess, TimeOfTravelProcess, TimeSurfaceProcess, VelocityProcess
from tofnet.testing import (TEST_INTRINSICS, LinearVelocity, camera_flow, directed_edge, flowing_pattern,
                            merge_events, moving_edge, moving_pattern, noise_events, turning_trajectory)

F = TEST_INTRINSICS.fx


@dataclass
class Scene:
    """What a case runs: a network, a recording, and the compiler's ``patch`` option."""

    network: Network
    recording: Recording
    patch: Any = None


@dataclass(frozen=True)
class Case:
    """A named conformance case; ``build()`` makes its scene (deterministic)."""

    name: str
    doc: str
    build: Callable[[], Scene] = field(repr=False)
    #: Steps at which every process's variables are compared too (through sessions).
    variables_at: tuple[int, ...] = ()


def net(sensor: tuple[int, int], velocity=(-0.5, 0.0, 0.0), *, refractory: Any = 0, t0: Any = 0,
        per: str = "pixel", patch_size: int = 30, update_every: int = 1, source: str = "constant",
        **tot_and_depth: Any) -> Network:
    """The paper's network for a case: refractory off and t0 = 0 unless given."""
    depth = {k: tot_and_depth.pop(k) for k in ("min_depth", "max_depth") if k in tot_and_depth}
    vel = {"source": source, "per": per, "patch_size": patch_size, "update_every": update_every}
    if source == "constant":
        vel["velocity"] = list(velocity)
    return depth_network(sensor, input={"refractory": refractory, "t0": t0}, time_of_travel=tot_and_depth,
                         depth=depth, velocity=vel)


def camera_for(flow_px_s: tuple[float, float], depth_m: float = 1.0) -> tuple[float, float, float]:
    """Camera velocity (m/s) that moves the image of a plane at ``depth_m`` by ``flow_px_s``."""
    return (-flow_px_s[0] * depth_m / F, -flow_px_s[1] * depth_m / F, 0.0)


def rec(*parts: np.ndarray, trajectory=None, intrinsics: Intrinsics = TEST_INTRINSICS) -> Recording:
    return Recording(merge_events(*parts), intrinsics=intrinsics, trajectory=trajectory)


CASES: list[Case] = []


def case(name: str, doc: str):
    """Register ``build`` as a case called ``name``."""
    def register(build: Callable[[], Scene]) -> Callable[[], Scene]:
        CASES.append(Case(name, doc, build))
        return build
    return register


def _add(name: str, doc: str, build: Callable[[], Scene]) -> None:
    CASES.append(Case(name, doc, build))


# -- edges in the four directions and the diagonals ------------------------------------------
DIRECTIONS = {"+u": (1, 0), "-u": (-1, 0), "+v": (0, 1), "-v": (0, -1),
              "+u+v": (1, 1), "+u-v": (1, -1), "-u+v": (-1, 1), "-u-v": (-1, -1)}
for _label, (_du, _dv) in DIRECTIONS.items():
    def _edge(du=_du, dv=_dv) -> Scene:
        flow = (250.0 * du, 250.0 * dv)  # 4 steps per pixel along each moving axis
        return Scene(net((12, 10), camera_for(flow)), rec(directed_edge((12, 10), flow)))
    _add(f"edge{_label}", f"a straight edge moving {_label} at 250 px/s per axis", _edge)

# -- every counter value up to overflow, and just past it ------------------------------------
for _count in range(1, 17):
    def _speed(count=_count) -> Scene:
        # 4-bit counters (max 15); Z = 200 px * 1 m/s * count * 1 ms = 0.2 m per count
        return Scene(net((6, 2), (-1.0, 0.0, 0.0), counter_bits=4),
                     rec(moving_edge((6, 2), 1000.0 / count)))
    _add(f"speed-4bit-{_count}", f"an edge taking {_count} steps per pixel; 4-bit counters "
         f"({'overflow' if _count > 15 else 'measured'})", _speed)
for _count in (254, 255, 256):
    def _speed8(count=_count) -> Scene:
        return Scene(net((4, 1), (-0.05, 0.0, 0.0)), rec(moving_edge((4, 1), 1000.0 / count)))
    _add(f"speed-8bit-{_count}", f"an edge taking {_count} steps per pixel; 8-bit counters", _speed8)


# -- textures and noise ----------------------------------------------------------------------
@case("texture-blobs", "random blobs moving diagonally (edges of every orientation, both polarities)")
def _blobs() -> Scene:
    flow = (300.0, -150.0)
    return Scene(net((24, 16), camera_for(flow)), rec(moving_pattern((24, 16), flow, 300_000, seed=1)))


@case("texture-checker", "a checkerboard moving -u+v, slowly (counts of 5-20 steps)")
def _checker() -> Scene:
    flow = (-120.0, 60.0)
    return Scene(net((20, 14), camera_for(flow, 2.0)),
                 rec(moving_pattern((20, 14), flow, 400_000, kind="checker", scale_px=5.0)))


@case("noise", "an edge under uniform background activity (20 Hz per pixel), refractory 1 ms")
def _noise() -> Scene:
    flow = (200.0, 0.0)
    return Scene(net((16, 12), camera_for(flow), refractory="1ms"),
                 rec(directed_edge((16, 12), flow), noise_events((16, 12), 20.0, 120_000, seed=3)))


# -- sensor borders, t0 and out-of-bounds events ---------------------------------------------
@case("borders", "edges entering from all four borders, events outside the sensor and before t0")
def _borders() -> Scene:
    size = (10, 8)
    parts = [directed_edge(size, flow, start_us=1000 + 40_000 * i)
             for i, flow in enumerate([(250, 0), (-250, 0), (0, 250), (0, -250)])]
    outside = make_events([1500, 2500, 3500, 45_000], [10, 11, 3, 10], [2, 3, 8, 9], [1, 0, 1, 1])
    before = make_events([100, 400, 900], [0, 1, 2], [0, 0, 0], [1, 1, 1])
    return Scene(net(size, camera_for((250, 0)), t0="1ms"), rec(*parts, outside, before))


# -- the compiled mapping: edges crossing core boundaries ------------------------------------
def _patch_scene(distance: int, patch: Any, size=(24, 16)) -> Scene:
    flow = (300.0, -150.0)
    parts = [directed_edge(size, (400 * du, 400 * dv), start_us=30_000 * i)
             for i, (du, dv) in enumerate([(1, 0), (-1, 0), (0, 1), (0, -1)])]
    parts.append(moving_pattern(size, flow, 200_000, seed=4, start_us=130_000))
    return Scene(net(size, camera_for(flow), distance=distance), rec(*parts), patch)


for _d in (1, 2):
    _add(f"patch-d{_d}", f"edges and a texture crossing 8x8 core boundaries, distance {_d}",
         lambda d=_d: _patch_scene(d, (8, 8)))
    _add(f"patch-d{_d}-ragged", f"25x17 px on 8x8 cores (ragged last row/column), depth on 12x9 cores, "
         f"distance {_d}", lambda d=_d: _patch_scene(d, {"time_of_travel": (8, 8), "depth": (12, 9)}, (25, 17)))
_add("patch-d2-thin", "cores one pixel wide (narrower than the distance 2 halo)",
     lambda: _patch_scene(2, (1, 5), (9, 10)))


# -- polarity, conflicts, drops --------------------------------------------------------------
@case("polarity-mix", "an ON edge then an OFF edge, and an edge whose rows alternate polarity")
def _polarity() -> Scene:
    size, flow = (12, 10), (250.0, 0.0)
    return Scene(net(size, camera_for(flow)), rec(
        directed_edge(size, flow, polarity=1), directed_edge(size, flow, polarity=0, start_us=20_000),
        directed_edge(size, (0, 250), polarity=lambda x, y: (x + y) % 2, start_us=60_000)))


@case("conflicting-directions", "edges meeting head-on (ties and smaller-count wins) and crossing at 90 deg")
def _conflict() -> Scene:
    size = (13, 9)
    return Scene(net(size, camera_for((250, 250))), rec(
        directed_edge(size, (250, 0)), directed_edge(size, (-250, 0)),
        directed_edge(size, (0, 300), start_us=80_000), directed_edge(size, (-200, 0), start_us=80_000),
        directed_edge(size, (330, 0), start_us=160_000), directed_edge(size, (-250, 0), start_us=160_000)))


@case("refractory", "bursts of 3 events per pixel 300 us apart under the default 5 ms refractory period")
def _refractory() -> Scene:
    size, flow = (12, 8), (150.0, 0.0)
    edge = directed_edge(size, flow)
    bursts = [edge.copy() for _ in range(3)]
    for i, burst in enumerate(bursts):
        burst["t"] += 300 * i
    again = directed_edge(size, flow, start_us=4000)  # inside the refractory period of the first
    return Scene(net(size, camera_for(flow), refractory="5ms"), rec(*bursts, again))


@case("same-step", "several events per pixel per step with a 100 us refractory period (same-step drops)")
def _same_step() -> Scene:
    size, flow = (12, 8), (200.0, 100.0)
    parts = [directed_edge(size, flow, polarity=i % 2, start_us=150 * i) for i in range(4)]
    return Scene(net(size, camera_for(flow), refractory="100us"), rec(*parts))


# -- the velocity term -----------------------------------------------------------------------
def _at_scene(per: str) -> Scene:
    size, flow = (24, 16), (-200.0, 150.0)
    cx, cy = 11.5, 7.5  # principal point inside the sensor: A t varies across it
    intr = Intrinsics(F, F, cx, cy)
    return Scene(net(size, (0.6, -0.4, 0.8), per=per, patch_size=5),
                 rec(moving_pattern(size, flow, 250_000, seed=5), intrinsics=intr))


_add("at-per-patch", "A t with forward motion, one value per 5x5 patch (the paper)", lambda: _at_scene("patch"))
_add("at-per-pixel", "A t with forward motion, exact at every pixel", lambda: _at_scene("pixel"))


@case("update-every", "velocity updates every 4 steps while the velocity ramps (ground-truth source)")
def _update_every() -> Scene:
    size, flow = (16, 12), (250.0, -120.0)
    ramp = LinearVelocity(camera_for(flow, 0.5), camera_for(flow, 3.0), 0.3)
    return Scene(net(size, source="groundtruth", update_every=4),
                 rec(moving_pattern(size, flow, 300_000, seed=6), trajectory=ramp))


@case("velocity-change", "the camera velocity reverses half-way, updated every step")
def _velocity_change() -> Scene:
    size, flow = (16, 12), (200.0, 0.0)
    ramp = LinearVelocity(camera_for(flow), camera_for((-flow[0], 0.0)), 0.2)
    return Scene(net(size, source="groundtruth"), rec(moving_pattern(size, flow, 200_000, seed=7), trajectory=ramp))


@case("depth-range", "depths on both sides of tight min/max limits (0.4 m, 1.2 m)")
def _depth_range() -> Scene:
    size = (16, 4)
    parts = [moving_edge(size, 1000.0 / count, start_us=60_000 * i) for i, count in enumerate((1, 2, 3, 4, 5, 6, 7))]
    return Scene(net(size, (-1.0, 0.0, 0.0), min_depth=0.4, max_depth=1.2), rec(*parts))


@case("empty", "no events at all")
def _empty() -> Scene:
    return Scene(net((4, 3)), rec(np.empty(0, dtype=EVENT_DTYPE)))


# -- graph shapes beyond the paper's chain --------------------------------------------------
def _constant(velocity) -> dict:
    return {"source": "constant", "velocity": list(velocity), "per": "pixel"}


@case("graph-two-distances", "one input feeding time of travel at distances 1 and 2, two depth outputs, "
      "one velocity process (fan-out), on 8x8 cores")
def _two_distances() -> Scene:
    size, flow = (24, 16), (300.0, -150.0)
    network = multi_distance_network(size, (1, 2), input={"refractory": 0, "t0": 0}, velocity=_constant(camera_for(flow)))
    return Scene(network, rec(moving_pattern(size, flow, 200_000, seed=8)), (8, 8))


@case("graph-denoised", "a background-activity filter (core-placed) between input and time of travel, under "
      "noise at 30 Hz per pixel, on 8x8 cores")
def _denoised() -> Scene:
    size, flow = (24, 16), (250.0, 100.0)
    network = denoised_network(size, input={"refractory": "1ms", "t0": 0}, denoise={"window": "4ms"},
                               velocity=_constant(camera_for(flow)))
    return Scene(network, rec(moving_pattern(size, flow, 200_000, seed=9), noise_events(size, 30.0, 200_000, seed=10)),
                 (8, 8))


@case("graph-undistort", "a barrel lens (k1 -0.3, f 20 px) undone by an undistort process (host) between input "
      "and time of travel: spikes moved, some leave the image; on 8x8 cores")
def _undistort() -> Scene:
    size, flow, lens = (24, 16), (250.0, 100.0), Intrinsics(20.0, 20.0, 11.5, 7.5, (-0.3, 0.1, 0.001, -0.002, 0.0))
    velocity = (-flow[0] / lens.fx, -flow[1] / lens.fy, 0.0)  # a plane at 1 m moves by flow px/s
    network = depth_network(size, input={"refractory": "1ms", "t0": 0}, undistort={}, velocity=_constant(velocity))
    return Scene(network, rec(moving_pattern(size, flow, 200_000, seed=15), intrinsics=lens), (8, 8))


@case("graph-user-process", "a process declared and registered outside tofnet's own (tofnet.testing."
      "ParityGateProcess), core-placed between input and time of travel with distance 2")
def _user_process() -> Scene:
    from tofnet.testing import ParityGateProcess
    size, flow = (20, 14), (-200.0, 250.0)
    inp = InputProcess(name="input", sensor_size=size, refractory=0, t0=0)
    gate = ParityGateProcess(name="gate", parity=1)
    tot = TimeOfTravelProcess(name="time_of_travel", distance=2)
    dep = DepthProcess(name="depth")
    vel = VelocityProcess(name="velocity", **_constant(camera_for(flow)))
    inp.events.connect(gate.events)
    gate.passed.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    network = Network([inp, gate, tot, dep, vel], name="user-process")
    return Scene(network, rec(moving_pattern(size, flow, 200_000, seed=11)), (7, 5))


def jittered(events: np.ndarray, jitter_us: int, seed: int) -> np.ndarray:
    """``events`` with each time moved later by up to ``jitter_us`` (µs), re-sorted: threshold mismatch."""
    rng = np.random.default_rng(seed)
    out = events.copy()
    out["t"] += rng.integers(0, jitter_us, len(out))
    return out[np.argsort(out["t"], kind="stable")]


@case("time-surface-texture", "the time-surface estimator (host process reading the events) on a jittered "
      "texture under noise; A t per pixel; microsecond times")
def _time_surface_texture() -> Scene:
    size, flow = (28, 20), (250.0, -120.0)
    network = improved_network(size, time_surface={"t0": 0}, velocity=_constant(camera_for(flow)))
    events = jittered(merge_events(moving_pattern(size, flow, 220_000, seed=15, sample_us=50, start_us=1_000),
                                   noise_events(size, 10.0, 220_000, seed=16)), 600, 17)
    return Scene(network, rec(events))


@case("time-surface-one-surface", "the time-surface estimator with one surface per pixel and polarity "
      "(burst_surfaces 1: a burst's later events not fitted), on the texture of time-surface-texture")
def _time_surface_one_surface() -> Scene:
    size, flow = (28, 20), (250.0, -120.0)
    network = improved_network(size, time_surface={"t0": 0, "burst_surfaces": 1}, velocity=_constant(camera_for(flow)))
    return Scene(network, _time_surface_texture().recording)


@case("graph-paper-and-time-surface", "the paper's network and the time-surface estimator side by side, both "
      "reading the events, on one velocity process; the texture of time-surface-texture")
def _paper_and_time_surface() -> Scene:
    size, flow = (28, 20), (250.0, -120.0)
    paper = depth_network(size, input={"refractory": "1ms", "t0": 0}, velocity=_constant(camera_for(flow)))
    surface = TimeSurfaceProcess(name="time_surface", sensor_size=size, t0=0)
    paper.process("velocity").a_t.connect(surface.a_t)
    events = jittered(merge_events(moving_pattern(size, flow, 160_000, seed=15, sample_us=50, start_us=1_000),
                                   noise_events(size, 10.0, 160_000, seed=16)), 600, 17)
    return Scene(Network([*paper.processes, surface], name="paper_and_time_surface"), rec(events))


# -- a turning camera (paper eq. 7) ----------------------------------------------------------
ROTATION_INTRINSICS = Intrinsics(F, F, 11.5, 7.5)  # principal point inside the sensor: B ω varies across it


def turning_net(size: tuple[int, int], velocity, omega=None, *, per: str = "pixel", patch_size: int = 30,
                update_every: int = 1, rotation_every: int = 1, source: str = "constant",
                min_share: float = 0.1, **depth: Any) -> Network:
    """The paper's network with an angular velocity process feeding the depth neurons (eq. 7)."""
    vel = {"source": source, "per": per, "patch_size": patch_size, "update_every": update_every}
    rot = {"source": source, "update_every": rotation_every}
    if source == "constant":
        vel["velocity"], rot["omega"] = list(velocity), list(omega)
    return depth_network(size, input={"refractory": 0, "t0": 0}, depth={"min_share": min_share, **depth},
                         velocity=vel, rotation=rot)


@case("rotation-texture", "a camera moving and turning about all three axes (constant ω) over a texture at 1 m; "
      "A t and B ω per pixel")
def _rotation_texture() -> Scene:
    size, velocity, omega = (24, 16), (-0.3, 0.15, 0.1), (0.1, -0.25, 0.15)
    flow = camera_flow(ROTATION_INTRINSICS, 1.0, velocity, omega)
    return Scene(turning_net(size, velocity, omega),
                 rec(flowing_pattern(size, flow, 250_000, seed=12), intrinsics=ROTATION_INTRINSICS))


@case("rotation-edges", "straight edges (a checkerboard) under pitch and a slide at 2 m; A t per 5x5 patch, "
      "ω updated every 3 steps, on 8x8 cores")
def _rotation_edges() -> Scene:
    size, velocity, omega = (24, 16), (-0.6, 0.2, 0.0), (0.3, 0.0, 0.0)
    flow = camera_flow(ROTATION_INTRINSICS, 2.0, velocity, omega)
    return Scene(turning_net(size, velocity, omega, per="patch", patch_size=5, rotation_every=3),
                 rec(flowing_pattern(size, flow, 300_000, kind="checker", scale_px=6.0), intrinsics=ROTATION_INTRINSICS),
                 (8, 8))


@case("rotation-poses", "velocity and ω from ground-truth poses of a camera sliding and yawing (1 kHz poses), "
      "on 7x5 cores")
def _rotation_poses() -> Scene:
    size, velocity, omega = (20, 14), (-0.4, 0.0, 0.05), (0.0, -0.2, 0.05)
    flow = camera_flow(ROTATION_INTRINSICS, 1.5, velocity, omega)
    return Scene(turning_net(size, velocity, omega, source="groundtruth"),
                 rec(flowing_pattern(size, flow, 250_000, seed=13), intrinsics=ROTATION_INTRINSICS,
                     trajectory=turning_trajectory(velocity, omega, 0.3)), (7, 5))


@case("rotation-dominated", "a pan (60 px/s of rotational flow) on a slow slide (10 px/s at 1 m): shares near "
      "min_share = 0.15, many rejected rotation_dominated, on 8x8 cores")
def _rotation_dominated() -> Scene:
    size, velocity, omega = (24, 16), (-0.05, 0.0, 0.0), (0.0, -0.3, 0.0)
    flow = camera_flow(ROTATION_INTRINSICS, 1.0, velocity, omega)
    return Scene(turning_net(size, velocity, omega, min_share=0.15),
                 rec(flowing_pattern(size, flow, 400_000, seed=14, scale_px=3.0), intrinsics=ROTATION_INTRINSICS),
                 (8, 8))


@case("time-surface-rotation", "the time-surface estimator with B ω (eq. 7): a camera sliding and turning over a "
      "texture at 1 m; A t per 5x5 patch, ω every 3 steps, min_denominator 0.5 (some rotation_dominated)")
def _time_surface_rotation() -> Scene:
    size, velocity, omega = (28, 20), (-0.3, 0.1, 0.05), (0.05, -0.2, 0.1)
    flow = camera_flow(ROTATION_INTRINSICS, 1.0, velocity, omega)
    network = improved_network(size, time_surface={"t0": 0, "min_denominator": 0.5},
                               velocity={"source": "constant", "velocity": list(velocity), "per": "patch",
                                         "patch_size": 5},
                               rotation={"source": "constant", "omega": list(omega), "update_every": 3})
    events = jittered(flowing_pattern(size, flow, 250_000, seed=18), 300, 19)
    return Scene(network, rec(events, intrinsics=ROTATION_INTRINSICS))


# -- state variables read mid-run (sessions) ------------------------------------------------
for _base, _steps in (("texture-blobs", (9, 60, 171)), ("patch-d2-ragged", (25, 90)), ("graph-denoised", (40, 120)),
                      ("update-every", (33, 150)), ("rotation-poses", (30, 110)), ("time-surface-texture", (50, 140))):
    _found = next(c for c in CASES if c.name == _base)
    CASES.append(Case(f"variables-{_base}", f"{_found.doc}; every variable compared at steps "
                      f"{', '.join(map(str, _steps))}", _found.build, _steps))


def get_case(name: str) -> Case:
    for c in CASES:
        if c.name == name:
            return c
    raise KeyError(name)
