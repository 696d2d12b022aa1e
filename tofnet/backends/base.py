"""What every backend takes and returns."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


#: Reasons the input process drops an event, in report order.
DROP_REASONS = ("out_of_bounds", "before_t0", "refractory", "same_step")
#: Reasons the depth process rejects an estimate, in report order.
REJECT_REASONS = ("no_measurement", "too_near", "too_far")

#: ``progress(done, total)``: called now and then with events processed so far.
ProgressCallback = Callable[[int, int], None]


@dataclass
class RunResult:
    """Depth estimates and the counts that account for every input event.

    ``depth`` is a ``DEPTH_DTYPE`` array; ``tot`` the time-of-travel spikes
    (``TOT_DTYPE``) when requested. ``events_in == accepted + sum(dropped.values())``.
    ``rejected`` counts depth neurons that received counters but emitted nothing.
    """

    backend: str
    depth: np.ndarray
    events_in: int
    accepted: int
    dropped: dict[str, int]
    rejected: dict[str, int]
    tot_spikes: int
    steps: int
    t0_us: int
    timestep_us: int
    latency_steps: int
    wall_time: float = 0.0
    tot: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    @property
    def latency_seconds(self) -> float:
        return self.latency_steps * self.timestep_us * 1e-6

    def summary(self) -> dict:
        """Plain-data summary (for JSON and the CLI)."""
        return {
            "backend": self.backend,
            "events_in": self.events_in,
            "accepted": self.accepted,
            "dropped": dict(self.dropped),
            "tot_spikes": self.tot_spikes,
            "depth_out": int(len(self.depth)),
            "rejected": dict(self.rejected),
            "steps": self.steps,
            "timestep_s": self.timestep_us * 1e-6,
            "latency_steps": self.latency_steps,
            "latency_s": self.latency_seconds,
            "wall_time_s": self.wall_time,
        }


def empty_counts(reasons: tuple[str, ...]) -> dict[str, int]:
    return {reason: 0 for reason in reasons}


class Backend(ABC):
    """Executes a compiled network on a recording.

    ``arithmetic`` is ``"float"`` or ``"fixed"``; integer backends must agree bit for
    bit, float ones within the tolerance stated in docs/fixed_point.md.
    """

    name: str = ""
    arithmetic: str = "float"

    @abstractmethod
    def run(self, compiled, recording, *, record_tot: bool = False,
            progress: ProgressCallback | None = None) -> RunResult:
        """Run ``compiled`` (a ``CompiledNetwork``) on ``recording`` (a ``Recording``)."""
