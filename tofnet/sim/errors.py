"""The simulator's error type."""

from __future__ import annotations

from tofnet.errors import TofnetError


class SimError(TofnetError):
    """A simulator scene, trajectory, scenario or parameter that cannot be simulated."""
