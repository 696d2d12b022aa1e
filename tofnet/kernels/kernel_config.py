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
from tofnet.kernels.lens import SAMPLE_COLUMNS, Lens, lens_of, sample_table


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


def counter_max(counter_bits: int) -> int:
    """Largest counter value before it overflows to 0: ``2**counter_bits - 1`` (steps)."""
    return (1 << int(counter_bits)) - 1


def microseconds(seconds: float) -> int:
    """``seconds`` as whole microseconds (events are stamped in µs): the one conversion."""
    return int(round(seconds * 1e6))


@dataclass(frozen=True)
class UnitSettings:
    """What the time-of-travel units take from a ``TimeOfTravelProcess``: ``distance`` (px) and
    ``counter_bits``, with the counter's largest value derived here."""

    distance: int
    counter_bits: int

    @property
    def counter_max(self) -> int:
        return counter_max(self.counter_bits)


#: The depth-side fields of a configuration whose kernel runs the units alone (``emit_depth``
#: False): not read, given so that the configuration is complete.
_UNITS_ALONE = dict(min_depth=0.05, max_depth=20.0, update_every=1, per_pixel=True, patch_size=1,
                    intrinsics=(1.0, 1.0, 0.0, 0.0), emit_depth=False)


@dataclass(frozen=True, kw_only=True)
class KernelConfig:
    """Everything the kernel needs besides spikes and velocities (plain data, picklable).

    ``timestep`` seconds, depths metres, ``intrinsics`` (fx, fy, cx, cy) pixels;
    ``fixed`` the fixed-point format, or None for float64 arithmetic; the input filter's
    ``refractory_us`` (µs) and ``refractory_per_polarity`` for ``process_events``;
    ``emit_depth`` False runs the time-of-travel units alone (no velocity needed);
    ``min_share`` (dimensionless) makes the depth layer alone (``process_counts``) compute
    eq. 7 from angular velocity updates, ``B ω`` evaluated with ``rotation_intrinsics``
    (``intrinsics`` when None); None keeps eq. 8. ``lens`` (model, coefficients): ``A t`` is
    taken through that lens onto the raw pixels (``tofnet.kernels.lens``); None: a pinhole.
    """

    sensor_size: tuple[int, int]
    timestep: float
    distance: int
    counter_bits: int
    min_depth: float
    max_depth: float
    update_every: int
    per_pixel: bool
    patch_size: int
    intrinsics: tuple[float, float, float, float]
    fixed: FixedPointFormat | None = None
    refractory_us: int = 0
    refractory_per_polarity: bool = False
    emit_depth: bool = True
    min_share: float | None = None
    rotation_intrinsics: tuple[float, float, float, float] | None = None
    lens: Lens | None = None

    @classmethod
    def from_pipeline(cls, pipeline, intrinsics, fixed: FixedPointFormat | None = None) -> "KernelConfig":
        """From a ``PipelineParams`` and an ``Intrinsics`` (its distortion is the lens)."""
        units = pipeline.units
        return cls(sensor_size=tuple(pipeline.sensor_size), timestep=pipeline.timestep, distance=units.distance,
                   counter_bits=units.counter_bits, min_depth=pipeline.min_depth, max_depth=pipeline.max_depth,
                   update_every=pipeline.update_every, per_pixel=pipeline.velocity_per == "pixel",
                   patch_size=pipeline.velocity_patch_size,
                   intrinsics=(intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy), fixed=fixed,
                   refractory_us=pipeline.refractory_us, refractory_per_polarity=pipeline.refractory_per_polarity,
                   lens=lens_of(intrinsics))

    @classmethod
    def units_alone(cls, sensor_size: tuple[int, int], timestep: float, units: UnitSettings) -> "KernelConfig":
        """The time-of-travel units without depth neurons (``timestep`` s): what the units' model runs."""
        return cls(sensor_size=tuple(sensor_size), timestep=timestep, distance=units.distance,
                   counter_bits=units.counter_bits, **_UNITS_ALONE)

    @property
    def timestep_us(self) -> int:
        return microseconds(self.timestep)

    @property
    def counter_max(self) -> int:
        """Largest counter value (``counter_max``)."""
        return counter_max(self.counter_bits)

    @property
    def seconds_per_count(self) -> float:
        """``dt / distance`` seconds, computed as the reference backend does."""
        return self.timestep / self.distance

    def check(self) -> None:
        """Raise ``BackendError`` when the fixed-point format cannot hold ``max_depth``."""
        if self.fixed is not None and self.max_depth > self.fixed.max_value:
            raise BackendError(
                f"max_depth {self.max_depth:g} m exceeds the fixed-point range {self.fixed.max_value:g} m "
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
    table = sample_table(config.per_pixel, config.patch_size, tuple(config.sensor_size), tuple(config.intrinsics),
                         config.lens)
    ys, xs = np.arange(r.y0, r.y1), np.arange(r.x0, r.x1)
    if config.per_pixel:
        rows, cols = (ys - r.y0) * w, xs - r.x0
    else:  # patches tile the sensor from (0, 0); the region overlaps a rectangle of them
        py, px = ys // config.patch_size, xs // config.patch_size
        rows, cols = (py - py[0]) * (px[-1] - px[0] + 1), px - px[0]
        # one pixel of each patch, in sample order: the first of the region inside it
        ys = ys[np.r_[0, np.flatnonzero(np.diff(py)) + 1]]
        xs = xs[np.r_[0, np.flatnonzero(np.diff(px)) + 1]]
    points = table[ys[:, None], xs[None, :]].reshape(-1, SAMPLE_COLUMNS)
    return rows, cols, points
