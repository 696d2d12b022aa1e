"""What a process model is: the code that runs one process on one backend family.

A model is built per process (per core region on ``multiproc``) with a ``ModelContext`` and
then advanced over ranges of steps: ``run(first, end, inputs)`` simulates steps
``first .. end-1``. ``inputs[port]`` holds every record sent to that port in steps
``first-1 .. end-2`` (the one-step delay of every connection), sorted by step; the model
returns, per output port, the records it sends in steps ``first .. end-1`` (the ``step``
field is the step of sending). Records are numpy structured arrays laid out by the port's
payload (``Payload.dtype``). ``StepModel`` turns a per-step ``step(k, inbox)`` into that.
"""

from __future__ import annotations

from contextlib import suppress
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from tofnet.core.process import Process
from tofnet.errors import BackendError
from tofnet.models.contract import checked_outputs, failures_named, who
from tofnet.units import seconds_of
from tofnet.kernels.fixed_point import FixedPointFormat
from tofnet.kernels.region import Region

FAMILIES = ("reference", "float", "fixed")


@dataclass
class ModelContext:
    """Everything a model is built with besides its process.

    ``family``: ``reference``, ``float`` or ``fixed``; ``fixed_format`` the fixed-point format
    (``tofnet.kernels.fixed_point.FixedPointFormat``) for ``fixed``, by default the ``fixed`` backend's
    (16 fractional bits, 24-bit payloads); ``t0_us`` the start of step 0 and ``timestep_us`` the
    step (µs); ``recording`` what is known about the camera
    (intrinsics, poses, IMU; its events are not for models) — None on a worker; ``region``
    the pixels this instance holds (None: all); ``inputs[port]`` the static descriptions
    (``output_meta``) of what feeds each input port, one per source.
    """

    family: str
    sensor_size: tuple[int, int]
    t0_us: int
    timestep_us: int
    fixed_format: Any = None
    recording: Any = None
    region: Region | None = None
    inputs: dict[str, list[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.family == "fixed" and self.fixed_format is None:  # the fixed backend's default, never float silently
            self.fixed_format = FixedPointFormat()

    @property
    def arithmetic(self) -> str:
        return "float" if self.family in ("reference", "float") else "fixed"

    @property
    def bounds(self) -> tuple[int, int, int, int]:
        """``(x0, x1, y0, y1)`` of the pixels held: the region, else the sensor."""
        if self.region is None:
            return (0, self.sensor_size[0], 0, self.sensor_size[1])
        r = self.region
        return (r.x0, r.x1, r.y0, r.y1)

    def input_meta(self, process: Process, port: str) -> Any:
        """The one description (``output_meta``) of what feeds ``port``; raises naming what is missing."""
        metas = [m for m in self.inputs.get(port) or [] if m is not None]
        if not metas or any(m != metas[0] for m in metas[1:]):
            what = "has no description from the process feeding it" if not metas else "is fed by sources that differ"
            raise BackendError(f"{process.name}.{port} {what} ({type(process).__name__} needs one: "
                               "see docs/extending.md, output_meta)")
        return metas[0]

    @property
    def timestep_s(self) -> float:
        """The timestep in seconds (``kernels.kernel_config.seconds_of``, as every model and the fused path)."""
        return seconds_of(self.timestep_us)


def holds_whole_numbers(process: Process) -> bool:
    """Whether ``process`` declares a ``vector`` variable: numbers of the whole process, which no merge of
    regions' values could give, so it never runs as regions (bands, cores)."""
    return any(var.shape == "vector" for var in type(process).vars)


def splits_into_regions(process: Process, model_class: type) -> bool:
    """Whether instances of ``model_class`` may each hold a region of ``process`` (bands, cores): the
    model says it can, and the process holds no whole-process numbers."""
    return bool(getattr(model_class, "supports_regions", False)) and not holds_whole_numbers(process)


def apply_param(instances: list[tuple[Process, "Model"]], name: str, value: Any) -> None:
    """Change parameter ``name`` of each ``(process, model)`` instance, all or none: the process holds
    the new value (converted and checked by its declaration) before its model is told, so a model
    reading ``self.process`` sees it (every backend, workers too); when one refuses, every process
    and the models told before it get the old value back, and the refusal is raised."""
    previous = [process.values.get(name) for process, _ in instances]
    told = []
    try:
        for process, model in instances:
            process.set_param(name, value)
            model.set_param(name, process.values[name])
            told.append((process, model))
    except BaseException:
        for (process, _), old in zip(instances, previous):
            process.set_param(name, old)
        for process, model in told:
            with suppress(Exception):  # it took the new value; the old one it held before
                model.set_param(name, process.values[name])
        raise


class Model:
    """Runs one process. Subclasses set the class attributes and implement ``run``."""

    #: True when the model takes the recording's events (``feed``) instead of input ports.
    reads_events: ClassVar[bool] = False
    #: True when one instance may hold a region of the sensor (``multiproc`` cores).
    supports_regions: ClassVar[bool] = False
    #: True for an event-reading model whose instance may hold a band of whole rows (``ctx.region``): fed
    #: every event, it keeps the state its rows need (its own halo) and counts and answers for its rows
    #: only, so workers run one instance per band (``tofnet.backends.bands``).
    runs_in_bands: ClassVar[bool] = False
    #: Why the model can only run on a host computer beside a neuromorphic chip, never as a process
    #: of one (empty: it can); a backend that builds chip processes (``lava``) refuses it with this.
    host_only: ClassVar[str] = ""

    def __init__(self, process: Process, ctx: ModelContext):
        self.process = process
        self.ctx = ctx

    @classmethod
    def latency_steps(cls, process: Process) -> dict[str, int]:
        """Per output port: the steps the model adds between what it receives (or reads) and what it
        sends there, beyond the one step of each connection: the declaration
        (``Process.port_latency_steps``). It stamps that output that much later; the executor adds
        it to the output's latency and runs that much longer."""
        return {spec.name: type(process).port_latency_steps(spec.name) for spec in process.outports}

    @classmethod
    def output_meta(cls, process: Process, ctx: ModelContext) -> dict[str, Any]:
        """Static descriptions of the output ports that receivers need (e.g. sampling, units)."""
        return {}

    def feed(self, events: np.ndarray) -> None:
        """Take camera events (``EVENT_DTYPE``, time order: ``GraphStream.feed_all`` checked); only for
        ``reads_events`` models."""
        raise BackendError(f"{self.process.name}: {type(self).__name__} does not read events")

    def complete_until(self) -> int | None:
        """For ``reads_events`` models: steps before this one have all their input (None: none yet)."""
        return None

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def counts(self) -> dict[str, int]:
        """What the process counted so far (drops, rejections, spikes), by reason."""
        return {}

    def get_var(self, name: str, step: int) -> np.ndarray:
        """Variable ``name`` (declared in ``process.vars``) at the start of ``step``: every step
        before it has run. Per-pixel variables cover the pixels this instance holds."""
        raise BackendError(f"{self.process.name} ({type(self.process).__name__}): its {type(self).__name__} "
                           f"does not expose the variable {name!r}")

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        """Replace variable ``name`` before ``step`` runs. ``value`` covers the whole sensor (per-pixel
        variables); an instance holding a region takes its pixels (and the halo copies it keeps)."""
        raise BackendError(f"{self.process.name} ({type(self.process).__name__}): its {type(self).__name__} "
                           f"cannot set the variable {name!r}")

    def set_param(self, name: str, value: Any) -> None:
        """Apply a parameter the session changed (already checked by the declaration) from the next
        step on; a model that reads the parameter only when built refuses."""
        raise BackendError(f"{self.process.name}.{name}: cannot change while the network runs "
                           f"({type(self).__name__} reads it when it is built); start a new session instead")

    def region_view(self, full: np.ndarray) -> np.ndarray:
        """The part of a full-sensor array (``[..., height, width]``) this instance holds."""
        x0, x1, y0, y1 = self.ctx.bounds
        return full[..., y0:y1, x0:x1]


class StepModel(Model):
    """A model written one step at a time: ``step(k, inbox) -> outbox``.

    ``inbox[port]`` is the records sent to ``port`` in step ``k-1`` (None when nothing
    was); ``outbox[port]`` the records to send in step ``k`` (None for nothing); their
    ``step`` field is set to ``k`` here. Readable and slow: it is called every step.
    """

    def step(self, k: int, inbox: dict[str, np.ndarray | None]) -> dict[str, np.ndarray | None]:
        raise NotImplementedError

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        cuts = {port: np.searchsorted(records["step"], np.arange(first - 1, end)) for port, records in inputs.items()}
        dtypes = {spec.name: spec.payload.dtype for spec in self.process.outports}
        parts: dict[str, list[np.ndarray]] = {port: [] for port in dtypes}
        name = who(self.process, type(self))
        for i, k in enumerate(range(first, end)):
            inbox = {}
            for port, records in inputs.items():
                lo, hi = cuts[port][i], cuts[port][i + 1]
                inbox[port] = records[lo:hi] if hi > lo else None
            with failures_named(name, f"step {k}"):  # the user's code: one line naming the process and step
                outbox = self.step(k, inbox)
            for port, sent in checked_outputs(name, self.process, outbox, f"step {k}", dtypes).items():
                if sent is not None and len(sent):
                    sent = np.array(sent, copy=True)
                    sent["step"] = k
                    parts[port].append(sent)
        return {port: concat(chunks, dtypes[port]) for port, chunks in parts.items()}


def concat(chunks: list[np.ndarray], dtype: np.dtype) -> np.ndarray:
    """One record array from several (an empty one of ``dtype`` when there are none)."""
    if not chunks:
        return np.empty(0, dtype=dtype)
    if len(chunks) == 1:
        return chunks[0]
    # joined as raw bytes: numpy copies packed records field by field otherwise (several times slower)
    raw = np.dtype((np.void, chunks[0].dtype.itemsize))
    return np.concatenate([np.ascontiguousarray(c).view(raw) for c in chunks]).view(chunks[0].dtype)


def take(records: np.ndarray, order: np.ndarray) -> np.ndarray:
    """``records[order]``, moved whole: numpy gathers packed records field by field when a record
    array is indexed with an index array (about 20x slower)."""
    return np.take(records, order)


def records(dtype: np.dtype, n: int = 0, **columns: Any) -> np.ndarray:
    """A record array of ``n`` rows (or as long as the columns) with the given columns filled."""
    if columns:
        n = len(next(iter(columns.values())))
    out = np.zeros(n, dtype=dtype)
    for name, values in columns.items():
        out[name] = values
    return out
