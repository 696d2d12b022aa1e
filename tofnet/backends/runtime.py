"""Binding a network to a recording: its clock and start time (the camera and velocity a process reads:
``tofnet.models.binding``)."""

from __future__ import annotations

from dataclasses import dataclass

from tofnet.core.network import Network
from tofnet.errors import NetworkError
from tofnet.io.recording import Recording
from tofnet.units import microseconds

#: The network's timestep when no process declares one (seconds).
DEFAULT_TIMESTEP = 1e-3


@dataclass(frozen=True)
class Clock:
    """The network's timestep (µs) and start of step 0 (µs; None: the first event's time)."""

    timestep_us: int
    t0_us: int | None


def clock_of(network: Network) -> Clock:
    """The one timestep (and ``t0``) every process that declares one agrees on.

    A network runs on one clock (Loihi's global timestep): processes with a ``timestep``
    or ``t0`` parameter must give the same value; none gives 1 ms and the first event.
    """
    def agreed(name: str):
        found = {p.name: p.values[name] for p in network.processes if name in p.values}
        values = set(found.values())
        if len(values) > 1:
            listing = ", ".join(f"{k}.{name} = {v!r}" for k, v in found.items())
            raise NetworkError(f"network {network.name!r}: processes disagree on {name} ({listing}); "
                               "a network runs on one clock")
        return next(iter(values)) if values else None, next(iter(found), None)

    timestep, owner = agreed("timestep")
    timestep = DEFAULT_TIMESTEP if timestep is None else timestep
    timestep_us = timestep * 1e6
    if abs(timestep_us - round(timestep_us)) > 1e-6 or round(timestep_us) < 1:
        raise NetworkError(f"{owner or network.name}.timestep: must be a whole number of microseconds, "
                           f"got {timestep * 1e6:.6g} µs")
    t0, _ = agreed("t0")
    return Clock(microseconds(timestep), None if t0 is None else microseconds(t0))


def start_time_us(t0_us: int | None, recording: Recording) -> int:
    """``t0`` in microseconds: the network's ``t0``, else the first event's time (0 without events)."""
    if t0_us is not None:
        return t0_us
    if len(recording.events) == 0:
        return 0
    return int(recording.events["t"][0])
