"""Lens undistortion of spikes: per step (reference) and event-driven (float, fixed alike).

Both look the spike's raw pixel up in one table, ``kernels.undistort.pixel_targets`` of the
process's lens (``UndistortProcess.lens``), so every family moves every spike to the same
pixel: the models differ only in how they loop.
"""

from __future__ import annotations

import numpy as np

from tofnet.core.ports import Payload
from tofnet.kernels.undistort import NEVER_STEP, pixel_targets, remap_spikes, undistortion_map
from tofnet.models.base import Model, ModelContext, StepModel
from tofnet.processes import UndistortProcess


def targets_for(process: UndistortProcess, ctx: ModelContext) -> np.ndarray:
    """``(height, width)`` int64: the undistorted pixel ``v' * width + u'`` of each raw pixel, -1 for none."""
    recording = ctx.recording
    where = recording.source if recording is not None and recording.source else "the recording"
    lens = process.lens(recording.intrinsics if recording is not None else None, where)
    return pixel_targets(undistortion_map(lens, ctx.sensor_size))


class UndistortStepModel(StepModel):
    """Every step: look each spike's target up, keep the first spike per target, send them in pixel order."""

    def __init__(self, process: UndistortProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        self.targets = targets_for(process, ctx)
        self.width = ctx.sensor_size[0]
        self.passed = self.left_image = self.merged = 0

    def step(self, k: int, inbox: dict) -> dict:
        spikes = inbox.get("events")
        if spikes is None:
            return {"undistorted": None}
        target = self.targets[spikes["y"].astype(np.int64), spikes["x"].astype(np.int64)]
        inside = target >= 0
        # np.unique: sorted targets (the canonical y, x order) and each one's first spike.
        unique, first = np.unique(target[inside], return_index=True)
        self.left_image += int((~inside).sum())
        self.merged += int(inside.sum()) - len(unique)
        self.passed += len(unique)
        out = np.zeros(len(unique), dtype=Payload.POLARITY.dtype)
        out["x"], out["y"] = unique % self.width, unique // self.width
        out["p"] = spikes["p"][inside][first]
        return {"undistorted": out}

    def counts(self) -> dict[str, int]:
        return {"passed": self.passed, "left_image": self.left_image, "merged": self.merged}


class UndistortEventModel(Model):
    """The same remap in one pass over a range of steps (``kernels.undistort.remap_spikes``)."""

    def __init__(self, process: UndistortProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        self.targets = targets_for(process, ctx)
        self.width = ctx.sensor_size[0]
        self.last_step = np.full(self.targets.size, NEVER_STEP, dtype=np.int64)
        self._counts = np.zeros(3, dtype=np.int64)
        self._dtype = Payload.POLARITY.dtype

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        spikes = inputs["events"]
        out = np.empty(len(spikes), self._dtype)
        received = np.ascontiguousarray(spikes["step"]) + 1  # sent in step k - 1, here in step k
        n = remap_spikes(received, spikes["x"], spikes["y"], spikes["p"],  # strided views, read in place
                         self.targets, self.width, self.last_step, out, self._counts)
        return {"undistorted": out[:n]}

    def counts(self) -> dict[str, int]:
        passed, left_image, merged = (int(c) for c in self._counts)
        return {"passed": passed, "left_image": left_image, "merged": merged}
