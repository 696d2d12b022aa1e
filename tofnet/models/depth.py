"""The depth process (paper eq. 8; eq. 7 with ``b_w``): dense per step (reference) and event-driven (float, fixed)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

import tofnet.numba_cache  # noqa: F401 - before any cached kernel: numba picks its cache key at decoration
from tofnet.core.counters import names_of
from tofnet.core.ports import Payload
from tofnet.kernels.depth import (EMITTED, ROTATION_DOMINATED, classify, classify_rotation, float_depth,
                                  float_depth_rotation, signed_axis_count, translational_share)
from tofnet.kernels.kernel_config import DepthSettings
from tofnet.kernels.region import KernelConfig, TimeOfTravelKernel
from tofnet.kernels.time_of_travel import N_REASONS
from tofnet.models.base import Model, ModelContext, StepModel, records
from tofnet.processes import DepthProcess

if TYPE_CHECKING:  # the fields' classes, for the hints only
    from tofnet.models.angular_velocity import RotationField
    from tofnet.models.velocity import VelocityField

#: Rejection reasons in the kernels' code order (``tofnet.kernels.depth``), as the process declares them.
REJECT_REASONS = names_of(DepthProcess.counters, "rejected")
#: Outcomes a depth neuron counts: the rejection reasons, then emitted estimates.
OUTCOMES = REJECT_REASONS + names_of(DepthProcess.counters, "output")
assert len(REJECT_REASONS) == N_REASONS and REJECT_REASONS[ROTATION_DOMINATED] == "rotation_dominated"


@njit(cache=True)
def _depth_neurons(counts, at_x, at_y, seconds_per_count, min_depth, max_depth, out_z, out_reason):
    for i in range(counts.shape[1]):
        sx = signed_axis_count(counts[0, i], counts[1, i])
        sy = signed_axis_count(counts[2, i], counts[3, i])
        z = float_depth(sx, sy, at_x[i], at_y[i], seconds_per_count)
        out_z[i] = z
        out_reason[i] = classify(sx != 0 or sy != 0, z, min_depth, max_depth)


@njit(cache=True)
def _depth_neurons_rotation(counts, at_x, at_y, bw_x, bw_y, seconds_per_count, min_share, min_depth, max_depth,
                            out_z, out_reason):
    for i in range(counts.shape[1]):
        sx = signed_axis_count(counts[0, i], counts[1, i])
        sy = signed_axis_count(counts[2, i], counts[3, i])
        share = translational_share(sx, sy, bw_x[i], bw_y[i], seconds_per_count)
        z = float_depth_rotation(sx, sy, at_x[i], at_y[i], bw_x[i], bw_y[i], seconds_per_count)
        out_z[i] = z
        out_reason[i] = classify_rotation(sx != 0 or sy != 0, share, z, min_share, min_depth, max_depth)


def depth_settings(process: DepthProcess, field: VelocityField, update_every: int = 1,
                   rotation: RotationField | None = None) -> DepthSettings:
    """What the depth neurons take: the process's depth range (m), the sampling of the ``A t`` feeding
    them (``field``, a ``VelocityField``, one update every ``update_every`` steps) and, with a
    ``rotation`` field feeding ``b_w`` (eq. 7), ``min_share`` and where ``B ω`` is evaluated (the
    depth model and the fused chain use this)."""
    return DepthSettings(min_depth=process.min_depth, max_depth=process.max_depth, per_pixel=field.per_pixel,
                         patch_size=field.patch_size, intrinsics=field.intrinsics, lens=field.lens,
                         update_every=update_every, min_share=None if rotation is None else process.min_share,
                         rotation_intrinsics=None if rotation is None else rotation.intrinsics)


def rotating(ctx: ModelContext) -> bool:
    """True when something feeds the depth process's ``b_w`` (eq. 7), from the descriptions of its inputs."""
    return bool(ctx.inputs.get("b_w"))


class DepthStepModel(StepModel):
    """Holds the latest ``A t`` (and ``B ω``) as dense arrays; turns the counters of a step into depths (float)."""

    def __init__(self, process: DepthProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        width, height = ctx.sensor_size
        self.field = ctx.input_meta(process, "a_t")
        self.seconds_per_count = ctx.input_meta(process, "counts").seconds_per_count
        self.at_x, self.at_y = np.zeros((height, width)), np.zeros((height, width))
        self.rotation = ctx.input_meta(process, "b_w") if rotating(ctx) else None
        self.bw_x, self.bw_y = np.zeros((height, width)), np.zeros((height, width))
        self.outcomes = dict.fromkeys(OUTCOMES, 0)
        self.width = width
        self._dtype = Payload.DEPTH.dtype

    def step(self, k: int, inbox: dict) -> dict:
        velocity = inbox.get("a_t")
        if velocity is not None:  # applied before this step's counters; the last update of a step wins
            last = velocity[-1]
            self.at_x, self.at_y = self.field.dense((last["tx"], last["ty"], last["tz"]))
        rotation = inbox.get("b_w")
        if rotation is not None:  # likewise
            last = rotation[-1]
            self.bw_x, self.bw_y = self.rotation.dense((last["wx"], last["wy"], last["wz"]))
        spikes = inbox.get("counts")
        if spikes is None:
            return {"depth": None}
        pixel = spikes["y"].astype(np.int64) * self.width + spikes["x"]
        pixels, slot = np.unique(pixel, return_inverse=True)
        counts = np.zeros((4, len(pixels)), dtype=np.int64)
        counts[spikes["direction"], slot] = spikes["count"]
        px, py = pixels % self.width, pixels // self.width
        z = np.empty(len(pixels))
        reason = np.empty(len(pixels), dtype=np.int64)
        if self.rotation is None:  # eq. 8
            _depth_neurons(counts, self.at_x[py, px], self.at_y[py, px], self.seconds_per_count,
                           self.process.min_depth, self.process.max_depth, z, reason)
        else:  # eq. 7
            _depth_neurons_rotation(counts, self.at_x[py, px], self.at_y[py, px], self.bw_x[py, px],
                                    self.bw_y[py, px], self.seconds_per_count, self.process.min_share,
                                    self.process.min_depth, self.process.max_depth, z, reason)
        for code, name in enumerate(REJECT_REASONS):
            self.outcomes[name] += int(np.count_nonzero(reason == code))
        keep = reason == EMITTED
        self.outcomes["emitted"] += int(np.count_nonzero(keep))
        t = self.ctx.t0_us + (k + 1) * self.ctx.timestep_us  # the end of the step
        return {"depth": records(self._dtype, t=np.full(int(keep.sum()), t), x=px[keep], y=py[keep], z=z[keep])}

    def counts(self) -> dict[str, int]:
        return dict(self.outcomes)

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "a_t":
            return np.stack([self.at_x, self.at_y])
        if name == "b_w":
            return np.stack([self.bw_x, self.bw_y])
        return super().get_var(name, step)


class DepthEventModel(Model):
    """The depth neurons of a region, event-driven, in the backend's arithmetic (docs/fixed_point.md)."""

    supports_regions = True

    def __init__(self, process: DepthProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        field = ctx.input_meta(process, "a_t")
        counts = ctx.input_meta(process, "counts")
        self.rotating = rotating(ctx)
        self.rotation = ctx.input_meta(process, "b_w") if self.rotating else None
        # the depth neurons fed counter spikes (the units are the sender's) and velocity rows as they come
        config = KernelConfig(sensor_size=tuple(ctx.sensor_size), timestep_us=ctx.timestep_us, units=counts.units,
                              depth=depth_settings(process, field, rotation=self.rotation), fixed=ctx.fixed_format)
        self.kernel = TimeOfTravelKernel(config, ctx.region, ctx.t0_us)
        self.field = field

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "a_t":  # the velocity update the neurons hold, as A t at every pixel
            return self.region_view(np.stack(self.field.dense(self.kernel._held_velocity[:3])))
        if name == "b_w":  # likewise the rotation update, as B ω (0 without rotation)
            if not self.rotating:
                width, height = self.ctx.sensor_size
                return self.region_view(np.zeros((2, height, width)))
            return self.region_view(np.stack(self.rotation.dense(self.kernel._held_omega)))
        return super().get_var(name, step)

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        rotation = inputs["b_w"] if self.rotating else None
        return {"depth": self.kernel.process_counts(inputs["counts"], inputs["a_t"], rotation)}

    def counts(self) -> dict[str, int]:
        return {name: int(c) for name, c in zip(OUTCOMES, self.kernel.outcomes)}
