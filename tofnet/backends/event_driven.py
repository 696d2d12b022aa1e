"""The event-driven backends: ``fixed`` (bit-exact integers) and ``float``.

Both run event-driven models (work proportional to events, not pixels x steps) and
differ only in the depth arithmetic (docs/fixed_point.md). The paper's chain runs
through one fused kernel (``tofnet.backends.fusion``); any other graph model by model.
"""

from __future__ import annotations

from tofnet.backends.local import LocalBackend
from tofnet.kernels.fixed_point import DEFAULT_FRAC_BITS, DEFAULT_PAYLOAD_BITS, FixedPointFormat


class FloatBackend(LocalBackend):
    """Event-driven float64 execution; equals the ``reference`` backend."""

    name = "float"
    arithmetic = "float"
    family = "float"
    fuses = True


class FixedBackend(LocalBackend):
    """Event-driven, bit-exact integer depth path (docs/fixed_point.md).

    ``frac_bits`` F and ``payload_bits`` P: ``W = A t * dt / distance`` and ``Z`` are
    signed P-bit integers in units of ``2**-F`` m.
    """

    name = "fixed"
    arithmetic = "fixed"
    family = "fixed"
    fuses = True

    def __init__(self, frac_bits: int = DEFAULT_FRAC_BITS, payload_bits: int = DEFAULT_PAYLOAD_BITS,
                 packet_events: int | None = None, fuse: bool = True, workers: int | str = 1):
        super().__init__(packet_events, fuse, workers)
        self.format = FixedPointFormat(frac_bits, payload_bits)

    def _format(self) -> FixedPointFormat:
        return self.format
