"""The paper's pipeline read off a network: resolved parameters every backend needs."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from tofnet.core.network import Network
from tofnet.errors import NetworkError
from tofnet.processes import DepthProcess, InputProcess, TimeOfTravelProcess, VelocityProcess


@dataclass(frozen=True)
class PipelineParams:
    """Resolved parameters of input -> time-of-travel -> depth <- velocity.

    Times in seconds, lengths in metres, sizes in pixels.
    """

    sensor_size: tuple[int, int]
    timestep: float
    t0: float | None
    refractory: float
    refractory_per_polarity: bool
    distance: int
    counter_bits: int
    min_depth: float
    max_depth: float
    velocity_source: str
    velocity_constant: tuple[float, float, float] | None
    velocity_samples: str | None
    velocity_per: str
    velocity_patch_size: int
    update_every: int
    intrinsics: tuple[float, float, float, float] | None
    names: tuple[str, str, str, str]  # input, time-of-travel, depth, velocity

    @property
    def timestep_us(self) -> int:
        """Timestep in whole microseconds (events are stamped in µs)."""
        return int(round(self.timestep * 1e6))

    @property
    def refractory_us(self) -> int:
        return int(round(self.refractory * 1e6))

    @property
    def counter_max(self) -> int:
        """Largest counter value before overflow: ``2**counter_bits - 1``."""
        return (1 << self.counter_bits) - 1

    @property
    def latency_steps(self) -> int:
        """Steps from an input event to its depth: one per connection (input->ToT->depth)."""
        return 2

    def to_dict(self) -> dict:
        return asdict(self)


def pipeline_of(network: Network) -> PipelineParams:
    """Find the paper's four processes in ``network`` and resolve their parameters.

    Raises ``NetworkError`` when the graph is not input -> time-of-travel -> depth,
    with a velocity process feeding the depth process.
    """
    def only(cls):
        found = network.of_type(cls)
        if len(found) != 1:
            raise NetworkError(f"network {network.name!r}: expected exactly one {cls.__name__}, found {len(found)}; "
                               "this backend runs input -> time_of_travel -> depth <- velocity")
        return found[0]

    inp, tot, depth, vel = (only(c) for c in (InputProcess, TimeOfTravelProcess, DepthProcess, VelocityProcess))
    expected = [(inp.events, tot.events), (tot.counts, depth.counts), (vel.a_t, depth.a_t)]
    for source, target in expected:
        if target.source is not source:
            actual = target.source.qualified_name if target.source else "nothing"
            raise NetworkError(f"{target.qualified_name} must be fed by {source.qualified_name}, not {actual}")
    timestep_us = inp.timestep * 1e6
    if abs(timestep_us - round(timestep_us)) > 1e-6:
        raise NetworkError(f"{inp.name}.timestep: must be a whole number of microseconds, got {inp.timestep!r} s")
    intrinsics = vel.intrinsics
    return PipelineParams(
        sensor_size=network.sensor_size,
        timestep=inp.timestep,
        t0=inp.t0,
        refractory=inp.refractory,
        refractory_per_polarity=inp.refractory_per_polarity,
        distance=tot.distance,
        counter_bits=tot.counter_bits,
        min_depth=depth.min_depth,
        max_depth=depth.max_depth,
        velocity_source=vel.source,
        velocity_constant=vel.velocity,
        velocity_samples=vel.samples,
        velocity_per=vel.per,
        velocity_patch_size=vel.patch_size,
        update_every=vel.update_every,
        intrinsics=tuple(intrinsics) if intrinsics is not None else None,
        names=(inp.name, tot.name, depth.name, vel.name),
    )
