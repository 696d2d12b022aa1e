"""What a time-of-travel kernel is built from: its region, its configuration, what a call returns.

Plain, picklable data (``multiproc`` sends configurations to workers) and the helpers that
lay out a region's ``A t`` samples; the kernel itself is ``tofnet.kernels.region``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from tofnet.errors import BackendError
from tofnet.kernels.fixed_point import FixedPointFormat
from tofnet.kernels.lens import SAMPLE_COLUMNS, Lens, sample_table
from tofnet.units import microseconds, seconds_of  # noqa: F401 - microseconds: the kernels' settings import it from here


#: ``Region.kinds``: where a pixel's column's kind is (its row's is at ``y``).
COLUMNS = 1 << 16


@dataclass(frozen=True)
class Region:
    """The pixels ``[x0, x1) x [y0, y1)`` whose units and depth neurons one kernel state holds."""

    x0: int
    x1: int
    y0: int
    y1: int

    @classmethod
    def full(cls, sensor_size: tuple[int, int]) -> "Region":
        return cls(0, int(sensor_size[0]), 0, int(sensor_size[1]))

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in pixels."""
        return self.y1 - self.y0, self.x1 - self.x0

    def feeds(self, xs: np.ndarray, ys: np.ndarray, distance: int) -> np.ndarray:
        """Mask of the spikes the region needs: inside it (triggers) or up to ``distance``
        pixels from it along its rows or columns (facilitations)."""
        xs, ys = np.asarray(xs, dtype=np.int64), np.asarray(ys, dtype=np.int64)
        in_x, in_y = (xs >= self.x0) & (xs < self.x1), (ys >= self.y0) & (ys < self.y1)
        near_x = (xs >= self.x0 - distance) & (xs < self.x1 + distance)
        near_y = (ys >= self.y0 - distance) & (ys < self.y1 + distance)
        return (in_y & near_x) | (in_x & near_y)

    def kinds(self, distance: int) -> np.ndarray:
        """Per row ``y`` (at ``y``) and column ``x`` (at ``COLUMNS + x``) of the uint16 range: 3 in the
        region, 1 within ``distance`` px of it only, else 0 (uint8); a pixel's kind is the AND of its
        row's and column's: the fused kernel's region and halo tests (``time_of_travel.process``' band)."""
        table = np.zeros(2 * COLUMNS, np.uint8)
        for at, lo, hi in ((0, self.y0, self.y1), (COLUMNS, self.x0, self.x1)):
            table[at + max(lo - distance, 0):at + hi + distance] = 1
            table[at + lo:at + hi] = 3
        return table


def counter_max(counter_bits: int) -> int:
    """Largest counter value before it overflows to 0: ``2**counter_bits - 1`` (steps)."""
    return (1 << int(counter_bits)) - 1


def seconds_per_count(timestep_us: int, distance: int) -> float:
    """``dt / distance`` (s): the time per pixel one counter step stands for (the depth neurons' scale)."""
    return seconds_of(timestep_us) / distance


# One typed settings object per kernel family, made from a process's parameters (units converted
# there, once) by the models' ``*_settings`` functions, which the models and the fused path share.

@dataclass(frozen=True, kw_only=True)
class InputFilterSettings:
    """What the input filter takes from an ``InputProcess``: ``refractory_us`` (µs; 0: none), kept
    per pixel or, with ``per_polarity``, per pixel and polarity."""

    refractory_us: int = 0
    per_polarity: bool = False


@dataclass(frozen=True, kw_only=True)
class UnitSettings:
    """What the time-of-travel units take from a ``TimeOfTravelProcess``: ``distance`` (px) and
    ``counter_bits``, with the counter's largest value derived here."""

    distance: int
    counter_bits: int

    @property
    def counter_max(self) -> int:
        return counter_max(self.counter_bits)


@dataclass(frozen=True, kw_only=True)
class DepthSettings:
    """What the depth neurons take from a ``DepthProcess`` and the ``A t`` (``B ω``) feeding it.

    Depths in metres; ``A t`` per pixel (``per_pixel``) or at the centre of ``patch_size`` px
    patches, evaluated with ``intrinsics`` (fx, fy, cx, cy) px through ``lens`` (None: a
    pinhole), one update every ``update_every`` steps. ``min_share`` (dimensionless) makes the
    neurons compute eq. 7 from angular velocity updates, ``B ω`` evaluated with
    ``rotation_intrinsics`` (``intrinsics`` when None); None keeps eq. 8.
    """

    min_depth: float
    max_depth: float
    per_pixel: bool
    patch_size: int
    intrinsics: tuple[float, float, float, float]
    lens: Lens | None = None
    update_every: int = 1
    min_share: float | None = None
    rotation_intrinsics: tuple[float, float, float, float] | None = None


#: The depth side of a configuration whose kernel runs the units alone: not read, there so that
#: the kernel's layout is complete.
UNITS_ALONE = DepthSettings(min_depth=0.05, max_depth=20.0, per_pixel=True, patch_size=1,
                            intrinsics=(1.0, 1.0, 0.0, 0.0))


@dataclass(frozen=True, kw_only=True)
class KernelConfig:
    """Everything the kernel needs besides spikes and velocities (plain data, picklable).

    ``timestep_us`` (µs) is the network's clock; ``units``, ``depth`` and ``input_filter`` the
    settings of each family (``depth`` None: the time-of-travel units alone, no velocity
    needed); ``fixed`` the fixed-point format, or None for float64 arithmetic.
    """

    sensor_size: tuple[int, int]
    timestep_us: int
    units: UnitSettings
    depth: DepthSettings | None = None
    input_filter: InputFilterSettings = InputFilterSettings()
    fixed: FixedPointFormat | None = None

    @property
    def emit_depth(self) -> bool:
        return self.depth is not None

    @property
    def neurons(self) -> DepthSettings:
        """The depth neurons' settings (``UNITS_ALONE``'s placeholders without depth neurons)."""
        return UNITS_ALONE if self.depth is None else self.depth

    @property
    def update_every(self) -> int:
        """Steps per velocity update (1 without depth neurons)."""
        return self.neurons.update_every

    @property
    def timestep(self) -> float:
        """Seconds (``seconds_of``)."""
        return seconds_of(self.timestep_us)

    @property
    def counter_max(self) -> int:
        """Largest counter value (``counter_max``)."""
        return self.units.counter_max

    @property
    def seconds_per_count(self) -> float:
        """``dt / distance`` seconds (``seconds_per_count``)."""
        return seconds_per_count(self.timestep_us, self.units.distance)

    def check(self) -> None:
        """Raise ``BackendError`` when the fixed-point format cannot hold ``max_depth``."""
        max_depth = self.neurons.max_depth
        if self.fixed is not None and max_depth > self.fixed.max_value:
            raise BackendError(
                f"max_depth {max_depth:g} m exceeds the fixed-point range {self.fixed.max_value:g} m "
                f"(payload_bits={self.fixed.payload_bits}, frac_bits={self.fixed.frac_bits}); "
                "lower max_depth or frac_bits, or raise payload_bits")


@dataclass
class KernelOutput:
    """What one ``process`` call produced.

    ``depth`` (``DEPTH_DTYPE``): step ``s``, stamp ``t0 + (s+1)*dt`` µs, pixel, ``z`` metres,
    in the order of the spikes that triggered them; ``z_raw`` their fixed-point values
    (units of ``2**-F`` m; 0 in float arithmetic; empty when written ``into`` a caller's
    buffer). ``tot`` the time-of-travel spikes (``TOT_DTYPE``) when asked for;
    ``tot_spikes`` how many units sent.
    """

    depth: np.ndarray
    z_raw: np.ndarray
    tot: np.ndarray | None
    tot_spikes: int


#: Velocity rows for the kernel: ``rows(first_update, n_updates)`` returns ``(table, table_first)``,
#: a table whose row ``i`` is update ``table_first + i`` (m/s, camera frame), covering the rows asked for.
VelocityRows = Callable[[int, int], tuple[np.ndarray, int]]
#: Largest velocity table one kernel call asks for; sparser input is split.
MAX_VELOCITY_ROWS = 1 << 16


def copy_records(records: np.ndarray) -> np.ndarray:
    """A copy of a contiguous structured array, moved as raw bytes (numpy copies packed records
    field by field: ~15x slower for a few thousand estimates)."""
    return records.view(np.dtype((np.void, records.dtype.itemsize))).copy().view(records.dtype)


def velocity_rows(steps: np.ndarray, update_every: int) -> tuple[int, int]:
    """``(first_update, n_updates)`` the depth neurons of the (sorted) input ``steps`` hold.

    A spike of input step ``k`` reaches its depth neuron in step ``s = k + 2``, which holds
    update ``(s - 1) // U`` (docs/semantics.md).
    """
    if len(steps) == 0:
        return 0, 0
    first = (int(steps[0]) + 1) // update_every
    return first, (int(steps[-1]) + 1) // update_every - first + 1


def _sample_tables(config: KernelConfig, r: Region) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``rows``, ``cols`` (the sample of pixel (x, y) is ``rows[y-y0] + cols[x-x0]``) and ``points``
    (one row of ``tofnet.kernels.lens.sample_table`` per sample: where ``A t`` is evaluated, the
    pixel or its patch centre, seen through the lens)."""
    (_, w) = r.shape
    depth = config.neurons
    table = sample_table(depth.per_pixel, depth.patch_size, tuple(config.sensor_size), tuple(depth.intrinsics),
                         depth.lens)
    ys, xs = np.arange(r.y0, r.y1), np.arange(r.x0, r.x1)
    if depth.per_pixel:
        rows, cols = (ys - r.y0) * w, xs - r.x0
    else:  # patches tile the sensor from (0, 0); the region overlaps a rectangle of them
        py, px = ys // depth.patch_size, xs // depth.patch_size
        rows, cols = (py - py[0]) * (px[-1] - px[0] + 1), px - px[0]
        # one pixel of each patch, in sample order: the first of the region inside it
        ys = ys[np.r_[0, np.flatnonzero(np.diff(py)) + 1]]
        xs = xs[np.r_[0, np.flatnonzero(np.diff(px)) + 1]]
    points = table[ys[:, None], xs[None, :]].reshape(-1, SAMPLE_COLUMNS)
    return rows, cols, points
