"""The background-activity filter: dense per step (reference) and event-driven (float, fixed alike)."""

from __future__ import annotations

import numpy as np

from tofnet.core.ports import Payload
from tofnet.kernels.background_filter import NEVER_STEP, filter_spikes
from tofnet.models.base import Model, ModelContext, StepModel
from tofnet.processes import BackgroundActivityFilterProcess
from tofnet.units import microseconds


def window_steps(process: BackgroundActivityFilterProcess, ctx: ModelContext) -> int:
    """The process's ``window`` in whole steps (rounded half up)."""
    return int(microseconds(process.window) / ctx.timestep_us + 0.5)


class BackgroundFilterStepModel(StepModel):
    """Every step: record the spikes that arrived, then pass those with a recent neighbour."""

    def __init__(self, process: BackgroundActivityFilterProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        width, height = ctx.sensor_size
        self.last = np.full((height, width), NEVER_STEP, dtype=np.int64)
        self.radius, self.window = int(process.radius), window_steps(process, ctx)
        self.passed = self.isolated = 0

    def step(self, k: int, inbox: dict) -> dict:
        spikes = inbox.get("events")
        if spikes is None:
            return {"passed": None}
        xs, ys = spikes["x"].astype(np.int64), spikes["y"].astype(np.int64)
        self.last[ys, xs] = k
        height, width = self.last.shape
        supported = np.zeros(len(spikes), dtype=bool)
        for dv in range(-self.radius, self.radius + 1):
            for du in range(-self.radius, self.radius + 1):
                if du == 0 and dv == 0:
                    continue
                nx, ny = xs + du, ys + dv
                inside = (nx >= 0) & (nx < width) & (ny >= 0) & (ny < height)
                recent = np.zeros(len(spikes), dtype=bool)
                recent[inside] = self.last[ny[inside], nx[inside]] >= k - self.window
                supported |= recent
        self.passed += int(supported.sum())
        self.isolated += int((~supported).sum())
        return {"passed": np.array(spikes[supported])}

    def counts(self) -> dict[str, int]:
        return {"passed": self.passed, "isolated": self.isolated}

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "last_spike":
            return self.last.copy()
        return super().get_var(name, step)

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        if name != "last_spike":
            return super().set_var(name, value, step)
        self.last[...] = value


class BackgroundFilterEventModel(Model):
    """The filter over a region of pixels (and its halo), in one pass over the spikes."""

    supports_regions = True

    def __init__(self, process: BackgroundActivityFilterProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        self.x0, self.x1, self.y0, self.y1 = ctx.bounds
        self.radius, self.window = int(process.radius), window_steps(process, ctx)
        self.pad = self.radius
        self.row = self.x1 - self.x0 + 2 * self.pad
        self.last = np.full((self.y1 - self.y0 + 2 * self.pad) * self.row, NEVER_STEP, dtype=np.int64)
        self._counts = np.zeros(2, dtype=np.int64)
        self._dtype = Payload.POLARITY.dtype

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        spikes = inputs["events"]
        out = np.empty(len(spikes), self._dtype)
        received = np.ascontiguousarray(spikes["step"]) + 1  # sent in step k - 1, here in step k
        n = filter_spikes(received, spikes["x"], spikes["y"], spikes["p"],
                          self.last, self.x0, self.y0, self.x1, self.y1, self.pad, self.row, self.radius,
                          self.window, out, self._counts)
        return {"passed": out[:n]}

    def counts(self) -> dict[str, int]:
        return {"passed": int(self._counts[0]), "isolated": int(self._counts[1])}

    def _inner(self) -> np.ndarray:
        """The region's own pixels of ``last`` (without the halo), ``[h, w]`` (a view)."""
        p = self.pad
        return self.last.reshape(-1, self.row)[p:-p, p:-p]

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "last_spike":
            return self._inner().copy()
        return super().get_var(name, step)

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        if name != "last_spike":
            return super().set_var(name, value, step)
        p, (width, height) = self.pad, self.ctx.sensor_size
        padded = np.full((height + 2 * p, width + 2 * p), NEVER_STEP, dtype=np.int64)
        padded[p:p + height, p:p + width] = value
        self.last.reshape(-1, self.row)[...] = padded[self.y0:self.y1 + 2 * p, self.x0:self.x1 + 2 * p]
