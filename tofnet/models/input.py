"""The input process on every backend family: the shared input filter, one spike per active pixel per step."""

from __future__ import annotations

import numpy as np

from tofnet.core.counters import names_of
from tofnet.core.ports import Payload
from tofnet.errors import BackendError
from tofnet.kernels.kernel_config import InputFilterSettings
from tofnet.units import microseconds
from tofnet.kernels.input_filter import ACCEPTED, NEVER, REFRACTORY, InputFilter, first_out_of_order
from tofnet.models.base import Model, ModelContext, concat, records
from tofnet.processes import InputProcess

#: Drop reasons in the filter's slot order (``tofnet.kernels.input_filter``), as the process declares them.
DROP_REASONS = names_of(InputProcess.counters, "dropped")
assert len(DROP_REASONS) == ACCEPTED and DROP_REASONS[REFRACTORY] == "refractory"


def filter_settings(process: InputProcess) -> InputFilterSettings:
    """What the input filter takes from the process, its refractory period in µs (the input model and the
    fused chain use this)."""
    return InputFilterSettings(refractory_us=microseconds(process.refractory),
                               per_polarity=bool(process.refractory_per_polarity))


def input_counts(events_in: int, accepted: int, drops) -> dict[str, int]:
    """The input process's counts (``InputProcess.counters``) from the filter's drop slots."""
    return {"events_in": int(events_in), "accepted": int(accepted),
            **{reason: int(c) for reason, c in zip(DROP_REASONS, drops)}}


def check_time_order(events: np.ndarray, after_us: int | None, who: str) -> None:
    """Refuse (before any state changes) events out of time order, or before ``after_us`` µs."""
    t = events["t"]
    i = first_out_of_order(t, NEVER if after_us is None else after_us)
    if i > 0:
        raise BackendError(f"{who}: events are not sorted by time: event {i} at {int(t[i])} µs follows "
                           f"{int(t[i - 1])} µs; feed events in time order")
    if i == 0:
        raise BackendError(f"{who}: events are not sorted by time: this packet starts at {int(t[0])} µs, before "
                           f"the previous packet's last event at {after_us} µs; the packet was refused and "
                           "the stream is unchanged")


class InputModel(Model):
    """Runs camera events through ``InputFilter`` as they are fed; sends the accepted ones in their step.

    An event accepted in step ``k`` is sent in step ``k`` with its polarity. Accepted spikes
    wait here until the executor runs their step, so packets may end anywhere.
    """

    reads_events = True

    def __init__(self, process: InputProcess, ctx: ModelContext):
        super().__init__(process, ctx)
        settings = filter_settings(process)
        self.filter = InputFilter(ctx.sensor_size, ctx.t0_us, ctx.timestep_us, refractory_us=settings.refractory_us,
                                  per_polarity=settings.per_polarity)
        self._waiting: list[np.ndarray] = []
        self._latest_us: int | None = None
        self._dtype = Payload.POLARITY.dtype

    def feed(self, events: np.ndarray) -> None:
        if len(events) == 0:
            return
        check_time_order(events, self._latest_us, self.process.name)
        steps, xs, ys, ps = self.filter.feed(events)
        self._latest_us = int(events["t"][-1])
        if len(steps):
            self._waiting.append(records(self._dtype, step=steps, x=xs, y=ys, p=ps))

    def complete_until(self) -> int | None:
        if self._latest_us is None or self._latest_us < self.ctx.t0_us:
            return None
        return (self._latest_us - self.ctx.t0_us) // self.ctx.timestep_us

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        waiting = concat(self._waiting, self._dtype)
        cut = int(np.searchsorted(waiting["step"], end))
        self._waiting = [waiting[cut:]] if cut < len(waiting) else []
        return {"events": waiting[:cut]}

    def _words(self) -> tuple[np.ndarray, int]:
        """The filter's last-accepted times per pixel ``[H, W, words]`` and the word of any polarity."""
        flt = self.filter
        return flt._last.reshape(flt.height, flt.width, -1), (2 if flt.per_polarity else 0)

    def get_var(self, name: str, step: int) -> np.ndarray:
        if name == "last_accepted":
            words, latest = self._words()
            return words[:, :, latest].copy()
        return super().get_var(name, step)

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        if name != "last_accepted":
            return super().set_var(name, value, step)
        words, _ = self._words()
        words[...] = np.asarray(value, dtype=np.int64)[:, :, None]  # the per-polarity words too

    def set_param(self, name: str, value) -> None:
        if name == "refractory":  # events fed from now on are filtered with the new period
            self.filter.refractory_us = microseconds(value)
            return
        super().set_param(name, value)

    def counts(self) -> dict[str, int]:
        flt = self.filter
        return input_counts(flt.events_in, flt.accepted, flt.drops)
