"""Streaming state of the time-of-travel units and depth neurons of one rectangular region.

The API every event-driven backend uses: the full-sensor ``fixed`` and ``float``
backends run one region covering the sensor; a multi-core backend runs one
``TimeOfTravelKernel`` per compiled core, feeding each the spikes ``Region.feeds`` selects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, TOT_DTYPE
from tofnet.kernels.fixed_point import FixedPointFormat
from tofnet.kernels.time_of_travel import (BASE, CURRENT, IDLE, NO_VELOCITY, PENDING_FULL, REBASE_AFTER, UNSORTED,
                                          process_spikes)
from tofnet.kernels.velocity import sample_grid


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


@dataclass(frozen=True)
class KernelConfig:
    """Everything the kernel needs besides spikes and velocities (plain data, picklable).

    ``timestep`` seconds, depths metres, ``intrinsics`` (fx, fy, cx, cy) pixels;
    ``fixed`` the fixed-point format, or None for float64 arithmetic.
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

    @classmethod
    def from_pipeline(cls, pipeline, intrinsics, fixed: FixedPointFormat | None = None) -> "KernelConfig":
        """From a ``PipelineParams`` and an ``Intrinsics``."""
        return cls(tuple(pipeline.sensor_size), pipeline.timestep, pipeline.distance, pipeline.counter_bits,
                   pipeline.min_depth, pipeline.max_depth, pipeline.update_every,
                   pipeline.velocity_per == "pixel", pipeline.velocity_patch_size,
                   (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy), fixed)

    @property
    def timestep_us(self) -> int:
        return int(round(self.timestep * 1e6))

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
    (units of ``2**-F`` m; 0 in float arithmetic). ``tot`` the time-of-travel spikes
    (``TOT_DTYPE``) when asked for; ``tot_spikes`` how many units sent.
    """

    depth: np.ndarray
    z_raw: np.ndarray
    tot: np.ndarray | None
    tot_spikes: int


def velocity_rows(steps: np.ndarray, update_every: int) -> tuple[int, int]:
    """``(first_update, n_updates)`` the depth neurons of the (sorted) input ``steps`` hold.

    A spike of input step ``k`` reaches its depth neuron in step ``s = k + 2``, which holds
    update ``(s - 1) // U`` (docs/semantics.md).
    """
    if len(steps) == 0:
        return 0, 0
    first = (int(steps[0]) + 1) // update_every
    return first, (int(steps[-1]) + 1) // update_every - first + 1


class TimeOfTravelKernel:
    """Units and depth neurons of one region, fed accepted input spikes packet by packet.

    Memory is fixed by the region (one int32 per unit, a buffer of one step's spikes and
    output buffers as large as the largest packet); it does not grow with the recording.
    """

    def __init__(self, config: KernelConfig, region: Region | None = None, t0_us: int = 0):
        config.check()
        self.t0_us = int(t0_us)  # start of input step 0, for the depth stamps
        self.config = config
        self.region = region if region is not None else Region.full(config.sensor_size)
        r, (width, height) = self.region, config.sensor_size
        if not (0 <= r.x0 < r.x1 <= width and 0 <= r.y0 < r.y1 <= height):
            raise BackendError(f"region {r} is not a non-empty part of the {width}x{height} sensor")
        (h, w), d = r.shape, config.distance
        self._stamp = np.full((h + 4 * d, w + 4 * d, 4), IDLE, dtype=np.int32)
        halo = (w + 2 * d) * (h + 2 * d)  # at most one spike per pixel and step
        self._pend = (np.zeros(halo, np.int64), np.zeros(halo, np.int64), np.zeros(halo, np.uint8))
        self._cursor = np.array([0, -1, 0], dtype=np.int64)  # buffered, current step, stamp base
        self._rebase_after = REBASE_AFTER
        self.rejected = np.zeros(3, dtype=np.int64)  # REJECT_REASONS order
        self.tot_spikes = 0
        # Where A t is evaluated: one point per pixel, or one per patch shared by its pixels.
        su, sv = sample_grid(config.per_pixel, config.patch_size, width, height)
        uv = np.stack([su[r.y0:r.y1, r.x0:r.x1].ravel(), sv[r.y0:r.y1, r.x0:r.x1].ravel()], axis=1)
        if config.per_pixel:
            self._points, index = uv, np.arange(h * w)
        else:
            ys, xs = np.divmod(np.arange(h * w), w)
            patch = ((ys + r.y0) // config.patch_size) * width + (xs + r.x0) // config.patch_size
            _, first, index = np.unique(patch, return_index=True, return_inverse=True)
            self._points = uv[first]
        self._points = np.ascontiguousarray(self._points)
        self._samples = index.reshape(h, w).astype(np.int64)
        n_points = len(self._points)
        self._cache = (np.full(n_points, -1, np.int64), np.zeros((n_points, 2)), np.zeros((n_points, 2), np.int64))
        fmt = config.fixed
        self._arith = (fmt is not None, config.seconds_per_count, config.min_depth, config.max_depth,
                       fmt.frac_bits if fmt else 0, fmt.payload_bits if fmt else 32,
                       fmt.quantize(config.min_depth) if fmt else 0, fmt.quantize(config.max_depth) if fmt else 0)
        self._out, self._raw, self._tot = np.empty(0, DEPTH_DTYPE), np.empty(0, np.int64), np.empty(0, TOT_DTYPE)
        self._broken = False

    def process(self, steps: np.ndarray, xs: np.ndarray, ys: np.ndarray, ps: np.ndarray,
                velocity_table: np.ndarray, first_update: int, *, record_tot: bool = False,
                copy: bool = True) -> KernelOutput:
        """Run accepted input spikes (input step, x, y, polarity) through the region.

        Spikes must be sorted by step and continue the previous call's; at most one per
        pixel and step (what ``InputFilter.feed`` returns). Spikes from anywhere on the
        sensor are accepted; those that neither trigger nor facilitate here are ignored.
        ``velocity_table[j - first_update]`` is the camera velocity (m/s, camera frame) of
        update ``j`` and must cover ``velocity_rows(steps, update_every)``; the same update
        must get the same row in every call (``A t`` is cached per update). ``copy=False``
        returns views of internal buffers, valid until the next call.
        """
        if self._broken:
            raise BackendError("kernel state is invalid after an earlier error; start a new one")
        cfg, r = self.config, self.region
        steps = np.ascontiguousarray(steps, dtype=np.int64)
        xs = np.ascontiguousarray(xs, dtype=np.int64)
        ys = np.ascontiguousarray(ys, dtype=np.int64)
        ps = np.ascontiguousarray(ps, dtype=np.uint8)
        velocity_table = np.ascontiguousarray(velocity_table, dtype=np.float64)
        n = len(steps)
        if n > len(self._out):  # reused across calls, grown geometrically
            size = max(n, 2 * len(self._out))
            self._out, self._raw = np.empty(size, DEPTH_DTYPE), np.empty(size, np.int64)
        if record_tot and 4 * n > len(self._tot):
            self._tot = np.empty(max(4 * n, 2 * len(self._tot)), TOT_DTYPE)
        n_out, n_tot, n_spikes, status = process_spikes(
            steps, xs, ys, ps, self._stamp.reshape(-1), self._cursor, *self._pend,
            r.x0, r.y0, r.x1, r.y1, cfg.distance, (1 << cfg.counter_bits) - 1, self._rebase_after,
            self._samples, self._points, *self._cache, velocity_table, first_update, cfg.update_every, *cfg.intrinsics,
            *self._arith, self.t0_us, cfg.timestep_us, self._out, self._raw, self.rejected,
            record_tot, self._tot)
        if status == NO_VELOCITY:
            first, count = velocity_rows(steps, cfg.update_every)
            raise BackendError(f"velocity table holds updates [{first_update}, {first_update + len(velocity_table)}); "
                               f"these spikes need [{first}, {first + count})")
        if status == UNSORTED:
            raise BackendError("input spikes are not sorted by step (events must be in time order and "
                               "each packet must follow the previous one)")
        if status == PENDING_FULL:
            self._broken = True
            raise BackendError("more than one input spike for one pixel in one step "
                               "(feed the spikes InputFilter accepted)")
        self.tot_spikes += n_spikes
        depth, raw, tot = self._out[:n_out], self._raw[:n_out], self._tot[:n_tot] if record_tot else None
        if copy:
            depth, raw, tot = depth.copy(), raw.copy(), tot.copy() if tot is not None else None
        return KernelOutput(depth, raw, tot, n_spikes)

    def unit_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Per unit of the region (``[H, W, 4]``): step of its last facilitation (-1: idle) and polarity.

        For tests and debugging; facilitations of a step still buffered are not included.
        """
        d = self.config.distance
        h, w = self.region.shape
        stamp = self._stamp[2 * d:2 * d + h, 2 * d:2 * d + w].astype(np.int64)
        idle = stamp == IDLE
        step = np.where(idle, -1, (stamp >> 1) + self._cursor[BASE])
        return step, np.where(idle, 0, stamp & 1).astype(np.int8)

    @property
    def current_step(self) -> int:
        """Input step of the latest spike processed (-1 before the first)."""
        return int(self._cursor[CURRENT])
