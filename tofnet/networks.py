"""Ready-made networks: the paper's depth network built from the four processes."""

from __future__ import annotations

from typing import Any

from tofnet.core.network import Network
from tofnet.processes import DepthProcess, InputProcess, TimeOfTravelProcess, VelocityProcess


def depth_network(sensor_size: tuple[int, int] = (240, 180), *, name: str = "depth",
                  input: dict[str, Any] | None = None, time_of_travel: dict[str, Any] | None = None,
                  depth: dict[str, Any] | None = None, velocity: dict[str, Any] | None = None) -> Network:
    """The paper's network: input -> time_of_travel -> depth <- velocity.

    Each dict overrides that process's parameters, e.g.
    ``depth_network(time_of_travel={"distance": 2}, velocity={"source": "constant", "velocity": [0.5, 0, 0]})``.
    """
    inp = InputProcess(name="input", sensor_size=sensor_size, **(input or {}))
    tot = TimeOfTravelProcess(name="time_of_travel", **(time_of_travel or {}))
    dep = DepthProcess(name="depth", **(depth or {}))
    vel = VelocityProcess(name="velocity", **(velocity or {}))
    inp.events.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    return Network([inp, tot, dep, vel], name=name)
