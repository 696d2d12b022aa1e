"""The time-of-travel process: Algorithm 1 step by step (reference) and event-driven (float, fixed)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.core.ports import Payload
from tofnet.errors import BackendError
from tofnet.events import DIRECTION_OFFSETS
from tofnet.kernels.kernel_config import UnitSettings, seconds_per_count
from tofnet.kernels.region import KernelConfig, TimeOfTravelKernel
from tofnet.kernels.unit_state import counters, set_counters
from tofnet.models.base import Model, ModelContext, StepModel, records
from tofnet.processes import TimeOfTravelProcess


def unit_settings(process: TimeOfTravelProcess) -> UnitSettings:
    """What the units take from the process (every time-of-travel model and the fused chain use this)."""
    return UnitSettings(distance=int(process.distance), counter_bits=int(process.counter_bits))


@dataclass(frozen=True)
class CountsInfo:
    """What receivers of counter spikes need: ``td = count * timestep / distance`` seconds per pixel."""

    units: UnitSettings
    timestep_us: int

    @property
    def distance(self) -> int:
        return self.units.distance

    @property
    def counter_max(self) -> int:
        return self.units.counter_max

    @property
    def seconds_per_count(self) -> float:
        """``dt / distance`` (s, ``seconds_per_count``: as every backend computes it)."""
        return seconds_per_count(self.timestep_us, self.units.distance)


class _SendsCounts:
    """The description of the ``counts`` port both models send."""

    @classmethod
    def output_meta(cls, process: TimeOfTravelProcess, ctx: ModelContext) -> dict:
        return {"counts": CountsInfo(units=unit_settings(process), timestep_us=ctx.timestep_us)}


def check_one_spike_per_pixel(process, step: int, xs: np.ndarray, ys: np.ndarray, width: int) -> None:
    pixel = ys.astype(np.int64) * width + xs
    if len(np.unique(pixel)) != len(pixel):
        raise BackendError(f"{process.name}.events: more than one spike for one pixel in step {step}; "
                           "a time-of-travel unit takes at most one (the input process sends one)")


def check_counter_values(process: TimeOfTravelProcess, name: str, value: np.ndarray) -> None:
    """Counters must be 0 (idle) .. the counter maximum; polarities 0 or 1."""
    top = unit_settings(process).counter_max if name == "counter" else 1
    if value.min(initial=0) < 0 or value.max(initial=0) > top:
        what = f"counter values must be in 0..{top} ({process.counter_bits}-bit counters)" if name == "counter" \
            else "polarity values must be 0 or 1"
        raise BackendError(f"{process.name}.{name}: {what}")


class TimeOfTravelStepModel(_SendsCounts, StepModel):
    """Algorithm 1 on dense state: a counter and a stored polarity per unit, every step."""

    def __init__(self, process: TimeOfTravelProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        width, height = ctx.sensor_size
        self.distance = int(process.distance)
        self.counter_max = unit_settings(process).counter_max
        self.counter = np.zeros((4, height, width), dtype=np.int64)
        self.polarity = np.zeros((4, height, width), dtype=np.int8)
        self.width, self.height = width, height
        self.sent = 0
        self._dtype = Payload.COUNT.dtype

    def step(self, k: int, inbox: dict) -> dict:
        spikes = inbox.get("events")
        sent = None
        if spikes is not None:
            xs, ys = spikes["x"].astype(np.int64), spikes["y"].astype(np.int64)
            ps = spikes["p"].astype(np.int8)
            check_one_spike_per_pixel(self.process, k - 1, xs, ys, self.width)
            # 1. triggers: every unit of an active pixel with a running counter and the same polarity.
            counts = self.counter[:, ys, xs]
            fire = (counts > 0) & (self.polarity[:, ys, xs] == ps[None, :])
            direction, index = np.nonzero(fire)
            sent = records(self._dtype, x=xs[index], y=ys[index], direction=direction,
                           count=counts[direction, index])
            self.counter[direction, ys[index], xs[index]] = 0
            self.sent += len(sent)
        # 2. running counters advance; past the maximum they overflow to 0.
        running = self.counter > 0
        self.counter[running] += 1
        self.counter[self.counter > self.counter_max] = 0
        # 3. facilitation: the unit an edge moving along D reaches next, distance pixels on.
        if spikes is not None:
            for direction, (du, dv) in enumerate(DIRECTION_OFFSETS):
                tx, ty = xs + du * self.distance, ys + dv * self.distance
                inside = (tx >= 0) & (tx < self.width) & (ty >= 0) & (ty < self.height)
                self.counter[direction, ty[inside], tx[inside]] = 1
                self.polarity[direction, ty[inside], tx[inside]] = ps[inside]
        return {"counts": sent}

    def counts(self) -> dict[str, int]:
        return {"spikes": self.sent}

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "counter":
            return self.counter.copy()
        if name == "polarity":
            return np.where(self.counter > 0, self.polarity, 0).astype(np.uint8)
        return super().get_var(name, step)

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        if name in ("counter", "polarity"):
            check_counter_values(self.process, name, value)
        if name == "counter":
            self.counter[...] = value
        elif name == "polarity":
            self.polarity[...] = value
        else:
            super().set_var(name, value, step)


class TimeOfTravelEventModel(_SendsCounts, Model):
    """The event-driven units (facilitation timestamps, ``tofnet.kernels.time_of_travel``) of a region."""

    supports_regions = True

    def __init__(self, process: TimeOfTravelProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        config = KernelConfig(sensor_size=tuple(ctx.sensor_size), timestep_us=ctx.timestep_us,
                              units=unit_settings(process))  # no depth neurons
        self.kernel = TimeOfTravelKernel(config, ctx.region, ctx.t0_us)
        self._no_velocity = np.zeros((0, 3))

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        spikes = inputs["events"]
        if not len(spikes):
            return {"counts": Payload.COUNT.empty()}
        step, x, y = spikes["step"], spikes["x"], spikes["y"]
        twice = np.flatnonzero((step[1:] == step[:-1]) & (x[1:] == x[:-1]) & (y[1:] == y[:-1]))
        if len(twice):  # inputs come in canonical order (step, y, x): a repeated pixel is adjacent
            check_one_spike_per_pixel(self.process, int(step[twice[0]]), x[twice[0]:twice[0] + 2],
                                      y[twice[0]:twice[0] + 2], self.ctx.sensor_size[0])
        out = self.kernel.process(spikes["step"], spikes["x"], spikes["y"], spikes["p"], self._no_velocity, 0,
                                  record_tot=True)
        return {"counts": out.tot}

    def counts(self) -> dict[str, int]:
        return {"spikes": self.kernel.tot_spikes}

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name in ("counter", "polarity"):
            counter, polarity = counters(self.kernel, step)
            return counter if name == "counter" else polarity
        return super().get_var(name, step)

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        if name not in ("counter", "polarity"):
            return super().set_var(name, value, step)
        check_counter_values(self.process, name, value)
        counter, polarity = counters(self.kernel, step)
        if name == "counter":
            counter = self.region_view(value)
        else:
            polarity = self.region_view(value)
        set_counters(self.kernel, counter, polarity, step)
