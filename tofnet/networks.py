"""Ready-made networks: the paper's depth network and the variants the examples use."""

from __future__ import annotations

from typing import Any, Iterable

from tofnet.core.network import Network
from tofnet.processes import (AngularVelocityProcess, BackgroundActivityFilterProcess, DepthProcess, InputProcess,
                              TimeOfTravelProcess, TimeSurfaceProcess, UndistortProcess, VelocityProcess)

#: The size (px) a network gets when given None, e.g. the ``sensor_size`` of a recording that names
#: none (an ECD folder without ``sensor_size.txt``): the Event Camera Dataset's DAVIS240C, as the CLI.
DEFAULT_SENSOR_SIZE = (240, 180)


def depth_network(sensor_size: tuple[int, int] | None = DEFAULT_SENSOR_SIZE, *, name: str = "depth",
                  input: dict[str, Any] | None = None, time_of_travel: dict[str, Any] | None = None,
                  depth: dict[str, Any] | None = None, velocity: dict[str, Any] | None = None,
                  rotation: dict[str, Any] | None = None, undistort: dict[str, Any] | None = None) -> Network:
    """The paper's network: input -> time_of_travel -> depth <- velocity.

    ``sensor_size`` (px) None, as a recording that names no size gives, is ``DEFAULT_SENSOR_SIZE``
    (so are the other builders').

    Each dict overrides that process's parameters, e.g.
    ``depth_network(time_of_travel={"distance": 2}, velocity={"source": "constant", "velocity": [0.5, 0, 0]})``.
    ``rotation`` (a dict, ``{}`` for the defaults) adds an ``AngularVelocityProcess`` called
    ``angular_velocity`` feeding ``depth.b_w``: the depth neurons then compensate the camera's
    rotation (paper eq. 7), e.g. ``rotation={"source": "gyro"}``. None: the paper's eq. 8.
    The velocity process takes a distorted lens into account (``VelocityProcess``), on raw pixels.
    ``undistort`` (a dict, ``{}`` for the recording's lens) instead puts an ``UndistortProcess``
    called ``undistort`` between input and time of travel: the network then works on the
    undistorted image (one step more latency) and the velocity process sees a pinhole.
    """
    inp = InputProcess(name="input", sensor_size=sensor_size or DEFAULT_SENSOR_SIZE, **(input or {}))
    tot = TimeOfTravelProcess(name="time_of_travel", **(time_of_travel or {}))
    dep = DepthProcess(name="depth", **(depth or {}))
    lens_free = {} if undistort is None else {"distortion_model": "none"}  # the pixels are undistorted already
    vel = VelocityProcess(name="velocity", **{**lens_free, **(velocity or {})})
    processes = [inp, tot, dep, vel]
    if undistort is None:
        inp.events.connect(tot.events)
    else:
        lens = UndistortProcess(name="undistort", **undistort)
        inp.events.connect(lens.events)
        lens.undistorted.connect(tot.events)
        processes.insert(1, lens)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    if rotation is not None:
        rot = AngularVelocityProcess(name="angular_velocity", **rotation)
        rot.b_w.connect(dep.b_w)
        processes.append(rot)
    return Network(processes, name=name)


def improved_network(sensor_size: tuple[int, int] | None = DEFAULT_SENSOR_SIZE, *, name: str = "improved",
                     time_surface: dict[str, Any] | None = None, velocity: dict[str, Any] | None = None,
                     rotation: dict[str, Any] | None = None) -> Network:
    """The time-surface estimator (beyond the paper, docs/time_surface.md): time_surface <- velocity.

    ``TimeSurfaceProcess`` reads the events itself (no input process) and outputs
    ``time_surface.depth`` (and the fits behind it on ``time_surface.quality``). ``A t`` is
    sent per pixel unless ``velocity`` says otherwise (the estimator's defaults were chosen
    with it). ``rotation`` (a dict, ``{}`` for the defaults) adds an ``AngularVelocityProcess``
    called ``angular_velocity`` feeding ``time_surface.b_w`` (eq. 7), as in ``depth_network``.
    """
    surface = TimeSurfaceProcess(name="time_surface", sensor_size=sensor_size or DEFAULT_SENSOR_SIZE,
                                 **(time_surface or {}))
    vel = VelocityProcess(name="velocity", **{"per": "pixel", **(velocity or {})})
    vel.a_t.connect(surface.a_t)
    processes = [surface, vel]
    if rotation is not None:
        rot = AngularVelocityProcess(name="angular_velocity", **rotation)
        rot.b_w.connect(surface.b_w)
        processes.append(rot)
    return Network(processes, name=name)


def multi_distance_network(sensor_size: tuple[int, int] | None = DEFAULT_SENSOR_SIZE,
                           distances: Iterable[int] = (1, 2), *,
                           name: str = "distances", input: dict[str, Any] | None = None,
                           depth: dict[str, Any] | None = None, velocity: dict[str, Any] | None = None) -> Network:
    """One input, one velocity, and a time-of-travel + depth branch per distance (the paper's Fig. 6b
    in one run): processes ``tot<d>`` and ``depth<d>``, outputs ``depth<d>.depth``."""
    inp = InputProcess(name="input", sensor_size=sensor_size or DEFAULT_SENSOR_SIZE, **(input or {}))
    vel = VelocityProcess(name="velocity", **(velocity or {}))
    processes = [inp]
    for d in distances:
        tot = TimeOfTravelProcess(name=f"tot{d}", distance=d)
        dep = DepthProcess(name=f"depth{d}", **(depth or {}))
        inp.events.connect(tot.events)
        tot.counts.connect(dep.counts)
        vel.a_t.connect(dep.a_t)
        processes += [tot, dep]
    return Network(processes + [vel], name=name)


def denoised_network(sensor_size: tuple[int, int] | None = DEFAULT_SENSOR_SIZE, *, name: str = "denoised",
                     input: dict[str, Any] | None = None, denoise: dict[str, Any] | None = None,
                     time_of_travel: dict[str, Any] | None = None, depth: dict[str, Any] | None = None,
                     velocity: dict[str, Any] | None = None) -> Network:
    """The paper's network with a background-activity filter between input and time of travel."""
    inp = InputProcess(name="input", sensor_size=sensor_size or DEFAULT_SENSOR_SIZE, **(input or {}))
    baf = BackgroundActivityFilterProcess(name="denoise", **(denoise or {}))
    tot = TimeOfTravelProcess(name="time_of_travel", **(time_of_travel or {}))
    dep = DepthProcess(name="depth", **(depth or {}))
    vel = VelocityProcess(name="velocity", **(velocity or {}))
    inp.events.connect(baf.events)
    baf.passed.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    return Network([inp, baf, tot, dep, vel], name=name)
