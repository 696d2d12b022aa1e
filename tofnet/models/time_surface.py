"""The time-surface process on every backend family: one event-driven model (``kernels/time_surface``).

The model reads the camera's events itself (``feed``/``complete_until``, as the input model),
with their microsecond times. An event of input step ``k`` is answered in step
``k + LATENCY_STEPS``; the model runs it once that step runs, with the ``A t`` (and ``B ω``)
update the step holds: the last one sent before it, from the ``a_t`` (``b_w``) records, as
the depth models take them. So any velocity process works, and a run in chunks of any size
gives the records of one run. The arithmetic is float64 on every family (the same model:
``reference``, ``float`` and ``fixed`` give the same bytes).
"""

from __future__ import annotations

import numpy as np

from tofnet.core.ports import Payload
from tofnet.errors import BackendError
from tofnet.events import EVENT_DTYPE
from tofnet.kernels.bands import clocked_columns
from tofnet.kernels.order import pixel_order
from tofnet.kernels.time_surface_estimator import TimeSurfaceConfig, TimeSurfaceEstimator, event_columns
from tofnet.kernels.time_surface_first import NEVER
from tofnet.models.base import Model, ModelContext, concat, records, take
from tofnet.processes.time_surface import QUALITY, TimeSurfaceProcess

#: A host process answers in the step after the event (the estimator's ``latency_steps``): what its
#: ``depth`` port declares (``quality`` goes with it).
LATENCY_STEPS = TimeSurfaceProcess.port_latency_steps("depth")
#: Process parameters that are ``TimeSurfaceConfig`` fields of the same name and unit.
CONFIG_PARAMS = ("model", "coordinates", "radius", "ahead_px", "window", "window_depth", "window_px", "turn",
                 "min_points", "min_spread", "outlier_px", "iterations", "max_rms_px", "trim_px", "hold_px",
                 "hold_fit_rms_px", "burst_ratio", "behind_depth", "refractory_depth", "refractory", "max_hold",
                 "consistency", "consistency_window", "min_depth", "max_depth", "min_denominator", "max_turn",
                 "burst_surfaces", "burst_fit")


def config_of(process: TimeSurfaceProcess, ctx: ModelContext) -> TimeSurfaceConfig:
    """The estimator's configuration: the process's parameters, the clock, and ``A t``'s sampling
    and the intrinsics from the descriptions of what feeds ``a_t`` (and ``b_w``)."""
    field = ctx.input_meta(process, "a_t")
    rotation = ctx.input_meta(process, "b_w") if ctx.inputs.get("b_w") else None
    return TimeSurfaceConfig(tuple(ctx.sensor_size), tuple(field.intrinsics),
                             **{name: getattr(process, name) for name in CONFIG_PARAMS},
                             timestep_us=ctx.timestep_us, latency_steps=LATENCY_STEPS, update_every=1,
                             per_pixel=field.per_pixel, patch_size=field.patch_size,
                             rotation_intrinsics=None if rotation is None else tuple(rotation.intrinsics),
                             lens=field.lens)


class HeldUpdates:
    """The updates of a field port as a step holds them: the last record sent before the step (zeros before any)."""

    def __init__(self, columns: tuple[str, ...]):
        self.columns = columns
        self.steps = np.empty(0, np.int64)
        self.values = np.empty((0, len(columns)))

    def add(self, received: np.ndarray) -> None:
        if len(received):
            self.steps = np.concatenate([self.steps, received["step"].astype(np.int64)])
            self.values = np.concatenate([self.values, np.stack([received[c] for c in self.columns], axis=1)])

    def held(self, sent_by: np.ndarray) -> np.ndarray:
        """Per entry of ``sent_by`` (steps): the last update sent at or before it, one row each."""
        i = np.searchsorted(self.steps, sent_by, side="right") - 1
        out = np.zeros((len(sent_by), len(self.columns)))
        have = i >= 0
        out[have] = self.values[i[have]]
        return out

    def forget_before(self, step: int) -> None:
        """Drop the updates no step from ``step`` on can hold (keeps the one held at ``step``)."""
        keep = max(int(np.searchsorted(self.steps, step, side="right")) - 1, 0)
        self.steps, self.values = self.steps[keep:], self.values[keep:]


class TimeSurfaceModel(Model):
    """Buffers the camera's events and runs them through ``TimeSurfaceEstimator`` when their answer's step runs."""

    reads_events = True
    runs_in_bands = True
    host_only = "is a float64 estimator that reads the camera's events itself (host-side, no chip arithmetic)"

    def __init__(self, process: TimeSurfaceProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        self.config = config_of(process, ctx)
        x0, x1, y0, y1 = ctx.bounds
        if (x0, x1) != (0, ctx.sensor_size[0]):
            raise BackendError(f"{process.name}: TimeSurfaceModel holds whole rows, not columns {x0}-{x1}")
        self.estimator = TimeSurfaceEstimator(self.config, ctx.t0_us, None if ctx.region is None else (y0, y1))
        self._keep = None if ctx.region is None else self._rows_read(y1)
        self.rotating = bool(ctx.inputs.get("b_w"))
        self.velocity = HeldUpdates(("tx", "ty", "tz"))
        self.rotation = HeldUpdates(("wx", "wy", "wz"))
        self._waiting: list[tuple[np.ndarray, ...]] = []  # event columns (t, x, y, p) not run yet
        self._latest_us: int | None = None
        self._depth, self._quality = Payload.DEPTH.dtype, QUALITY.dtype

    # -- events -------------------------------------------------------------------------------
    def _rows_read(self, own_end: int) -> np.ndarray:
        """A band's rows whose events it reads (uint8 per ``y``, 65536 entries): the rows it holds, and
        for the last band (it counts them) the rows past the sensor."""
        keep = np.zeros(1 << 16, np.uint8)
        lo, hi = self.estimator.held
        keep[lo:hi] = 1
        if own_end >= self.ctx.sensor_size[1]:
            keep[self.ctx.sensor_size[1]:] = 1
        return keep

    def _columns(self, events: np.ndarray) -> tuple[np.ndarray, ...]:
        """The columns of the events this model runs (copies: the caller may reuse its buffer). A band's:
        the events of its rows and each step's first event, which moves the kernel's clock (travel ring,
        motion epochs) where the whole sensor's moves it; the kernel skips the rest of another band's
        events, so its output and counts are the same as when fed every event, for a fraction of the walk."""
        if self._keep is None or events.dtype != EVENT_DTYPE:
            return event_columns(events)
        width, height = self.ctx.sensor_size
        m, *columns = clocked_columns(events, self._keep, self.ctx.t0_us, self.ctx.timestep_us, width, height)
        if m < 0:  # out of time order: every event, so the kernel refuses it where one whole kernel would
            return event_columns(events)
        return tuple(c[:m] for c in columns)

    def feed(self, events: np.ndarray) -> None:
        if len(events) == 0:
            return
        # no time-order check here: the stream, the only feeder, refused such a packet, and the kernel checks too
        self._waiting.append(self._columns(events))
        self._latest_us = int(events["t"][-1])

    def complete_until(self) -> int | None:
        if self._latest_us is None or self._latest_us < self.ctx.t0_us:
            return None
        return (self._latest_us - self.ctx.t0_us) // self.ctx.timestep_us

    def _take_events(self, before_us: int) -> list[tuple[np.ndarray, ...]]:
        """The waiting events earlier than ``before_us`` µs, as column pieces (removed from the queue)."""
        taken = []
        while self._waiting:
            columns = self._waiting[0]
            cut = int(np.searchsorted(columns[0], before_us, side="left"))
            if cut:
                taken.append(tuple(c[:cut] for c in columns))
            if cut < len(columns[0]):
                self._waiting[0] = tuple(c[cut:] for c in columns)
                break
            self._waiting.pop(0)
        return taken

    # -- running ------------------------------------------------------------------------------
    def _rows(self, first_update: int, count: int) -> tuple[np.ndarray, int]:
        """Velocity rows for updates ``first_update ..``: update ``j`` is what output step ``j + 1`` holds,
        the last update sent at or before step ``j`` (``update_every`` 1 in the estimator's terms)."""
        sent_by = np.arange(first_update, first_update + count, dtype=np.int64)
        table = self.velocity.held(sent_by)
        if self.rotating:
            table = np.concatenate([table, self.rotation.held(sent_by)], axis=1)
        return table, first_update

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self.velocity.add(inputs["a_t"])
        if self.rotating:
            self.rotation.add(inputs["b_w"])
        # The events answered in steps [first, end): input steps before end - LATENCY_STEPS.
        pieces = self._take_events(self.ctx.t0_us + (end - LATENCY_STEPS) * self.ctx.timestep_us)
        answers = [self.estimator.feed_columns(*columns, self._rows) for columns in pieces]
        self.velocity.forget_before(end - 1)
        self.rotation.forget_before(end - 1)
        if not answers:
            return {"depth": np.empty(0, self._depth), "quality": np.empty(0, self._quality)}
        depth = concat([d for d, _ in answers], self._depth)
        quality = concat([q for _, q in answers], answers[0][1].dtype)  # the estimator's, not the port's
        # The canonical order (step, y, x; events in time order within a pixel's step), sorted once for both:
        # the estimates come in event order, so by step already.
        order = pixel_order(depth["step"], depth["y"], depth["x"], np.zeros(len(depth), np.uint8),
                            self.ctx.sensor_size[1])
        depth, quality = take(depth, order), take(quality, order)
        fit = records(self._quality, step=depth["step"], x=depth["x"], y=depth["y"], t_event=quality["t_event"],
                      points=quality["points"], rms_px=quality["rms_px"], gx=quality["gx"], gy=quality["gy"])
        return {"depth": depth, "quality": fit}

    def counts(self) -> dict[str, int]:
        counts = self.estimator.counts
        # every event it counted (a band counts those of its rows)
        return {"events_in": sum(counts.values()), "accepted": self.estimator.first_events, **counts}

    # -- state between runs -------------------------------------------------------------------
    def _surface(self) -> np.ndarray:
        """A view of the surfaces ``[2 K, rows held, W]`` (µs) inside the kernel's border: ``[:2]`` the first
        events' (``last_first_event``), then per burst index ``k < K`` (``burst_surfaces``) two more."""
        width, r = self.ctx.sensor_size[0], self.config.radius
        height = self.estimator.held[1] - self.estimator.held[0]
        return self.estimator._surface.reshape(-1, height + 2 * r, width + 2 * r)[:, r:r + height, r:r + width]

    def _hold(self) -> np.ndarray:
        """A view of the holds ``[2, rows held, W]`` (µs)."""
        width = self.ctx.sensor_size[0]
        return np.moveaxis(self.estimator._hold.reshape(-1, width, 2), 2, 0)

    def _own(self, held: np.ndarray) -> np.ndarray:
        """The rows of the region (the sensor's, or a band's) of an array over the rows held."""
        _, _, y0, y1 = self.ctx.bounds
        return held[:, y0 - self.estimator.held[0]:y1 - self.estimator.held[0]]

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "last_first_event":
            return self._own(self._surface()[:2]).copy()
        if name == "hold":
            return self._own(self._hold()).astype(np.int64)
        return super().get_var(name, step)

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        lo, hi = self.estimator.held  # a band takes its halo rows too: its fits read their surface
        if name == "last_first_event":
            surfaces, value = self._surface(), value[:, lo:hi]
            changed = surfaces[:2] != value  # where an edge is forgotten or planted: its later events' too
            for k in range(1, len(surfaces) // 2):
                surfaces[2 * k:2 * k + 2][changed] = NEVER
            surfaces[:2] = value
            return
        if name == "hold":
            self._hold()[...] = np.clip(value[:, lo:hi], 0, np.iinfo(np.int32).max)
            return
        super().set_var(name, value, step)
