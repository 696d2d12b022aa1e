"""The Lava processes a tofnet graph becomes (lava-nc 0.10, Python 3.10; imported only by the lava backend).

Per tofnet process, one ``AbstractProcess`` subclass generated for it: an ``InPort`` per
connection into it (``in_PORT``, or ``in_PORT_1``, ``in_PORT_2`` ... under fan-in), an
``OutPort`` per output port (``out_PORT``), a ``Var`` per declared variable (its tofnet name)
and ``tally`` (its counts). Its
``PyLoihiProcessModel`` (tagged ``fixed_pt`` or ``floating_pt``) holds the tofnet model of
its family and calls ``model.run(k, k + 1, inputs)`` once per Lava time step: the
arithmetic is tofnet's, written once. Besides them, ``EventSource`` sends each step's
camera events to the processes that read events, and one ``RecordSink`` per sink or
probed port hands what it receives back to the host.

A message is one dense ``int64`` vector per port and step: word 0 the number of records,
then the records' bytes (``pack``/``unpack``). Lava's Python channels deliver a message
within the step it is sent in; a tofnet process keeps what it received in step ``k`` and
runs it in step ``k + 1`` — the one-step delay of every connection, as Lava's ``Dense``
buffers its output for a step.
"""

from __future__ import annotations

import multiprocessing
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from lava.magma.core.decorator import implements, requires, tag
from lava.magma.core.model.py.model import PyLoihiProcessModel
from lava.magma.core.model.py.ports import PyInPort, PyOutPort
from lava.magma.core.model.py.type import LavaPyType
from lava.magma.core.process.ports.ports import InPort, OutPort
from lava.magma.core.process.process import AbstractProcess
from lava.magma.core.process.variable import Var
from lava.magma.core.resources import CPU
from lava.magma.core.sync.protocols.loihi_protocol import LoihiProtocol

from tofnet.backends.graph import canonical
from tofnet.errors import BackendError, TofnetError
from tofnet.events import EVENT_DTYPE
from tofnet.models.base import concat

#: Lava tag of each tofnet model family.
TAGS = {"fixed": "fixed_pt", "float": "floating_pt", "reference": "floating_pt"}
#: The in-port of an event-reading process that the source feeds.
CAMERA_PORT = "in_camera"


def words_for(records: int, dtype: np.dtype) -> int:
    """Length of a message holding up to ``records`` records of ``dtype`` (header word included)."""
    return 1 + -(-records * np.dtype(dtype).itemsize // 8)


def pack(records: np.ndarray, words: int, what: str, out: np.ndarray | None = None) -> np.ndarray:
    """``records`` as one message of ``words`` int64 words (into ``out`` when given: a port's buffer,
    reused because Lava copies what is sent; words past the records are left as they are);
    raises naming ``what`` when they do not fit."""
    nbytes = len(records) * records.dtype.itemsize
    if 8 + nbytes > 8 * words:
        raise BackendError(f"{what}: {len(records)} records in one step, more than its Lava port holds "
                           f"({(8 * words - 8) // records.dtype.itemsize})")
    out = np.zeros(words, np.int64) if out is None else out
    out[0] = len(records)
    out[1:].view(np.uint8)[:nbytes] = np.ascontiguousarray(records).view(np.uint8)
    return out


def unpack(message: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """The records of one message (a copy: the channel's buffer is reused)."""
    words = np.ascontiguousarray(message, dtype=np.int64).ravel()
    n = int(words[0])
    return words[1:].view(np.uint8)[:n * dtype.itemsize].copy().view(dtype)


# -- the source and the sinks ------------------------------------------------------------------------

class EventSource(AbstractProcess):
    """Sends, in step ``k``, the camera events of tofnet step ``k`` (those before ``t0`` in step 0).

    The host puts ``(end, events)`` on ``feed`` before running to step ``end``; ``events`` are
    those of steps before ``end`` not sent yet.
    """

    def __init__(self, *, words: int, feed: Any, t0_us: int, timestep_us: int, **kwargs):
        super().__init__(words=words, feed=feed, t0_us=t0_us, timestep_us=timestep_us, **kwargs)
        self.events = OutPort(shape=(words,))


@implements(proc=EventSource, protocol=LoihiProtocol)
@requires(CPU)
@tag("fixed_pt", "floating_pt")
class PyEventSourceModel(PyLoihiProcessModel):
    events: PyOutPort = LavaPyType(PyOutPort.VEC_DENSE, np.int64)

    def __init__(self, proc_params):
        super().__init__(proc_params)
        self.words, self.feed = proc_params["words"], proc_params["feed"]
        self.t0_us, self.timestep_us = proc_params["t0_us"], proc_params["timestep_us"]
        self.end = 0
        self.pending = np.empty(0, EVENT_DTYPE)

    def run_spk(self) -> None:
        k = self.time_step - 1
        while k >= self.end:  # the host put one message per run, before starting it
            self.end, events = self.feed.get()
            self.pending = concat([self.pending, events], EVENT_DTYPE) if len(events) else self.pending
        cut = int(np.searchsorted(self.pending["t"], self.t0_us + (k + 1) * self.timestep_us))
        now, self.pending = self.pending[:cut], self.pending[cut:]
        self.events.send(pack(now, self.words, "the event source"))


class RecordSink(AbstractProcess):
    """Receives one output port's records each step and puts ``(step, records)`` on ``out``."""

    def __init__(self, *, words: int, dtype: np.dtype, out: Any, **kwargs):
        super().__init__(words=words, dtype=dtype, out=out, **kwargs)
        self.records = InPort(shape=(words,))


@implements(proc=RecordSink, protocol=LoihiProtocol)
@requires(CPU)
@tag("fixed_pt", "floating_pt")
class PyRecordSinkModel(PyLoihiProcessModel):
    records: PyInPort = LavaPyType(PyInPort.VEC_DENSE, np.int64)

    def run_spk(self) -> None:
        got = unpack(self.records.recv(), self.proc_params["dtype"])
        self.proc_params["out"].put((self.time_step - 1, got if len(got) else None))


# -- one process per tofnet process --------------------------------------------------------------------

@dataclass
class Plan:
    """What a generated Lava process needs: the tofnet model it runs and how its ports map.

    ``inputs[port]``: the Lava in-ports (one per connection) of tofnet input ``port``, in the
    executor's order; ``outputs[port]``: ``(lava out-port, words)``; ``in_words``: each
    in-port's message length; ``vars``: the declared variables ``{name: (shape, dtype)}``;
    ``tally``: the count keys in order; ``failures``: where a failing step is reported.
    """

    name: str
    model: Any
    dtypes: dict[str, np.dtype]
    inputs: dict[str, list[str]] = field(default_factory=dict)
    outputs: dict[str, tuple[str, int]] = field(default_factory=dict)
    in_words: dict[str, int] = field(default_factory=dict)
    vars: dict[str, tuple[tuple[int, ...], np.dtype]] = field(default_factory=dict)
    tally: list[str] = field(default_factory=list)
    reads_events: bool = False
    source_words: int = 0
    failures: Any = None


class TofnetLavaProcess(AbstractProcess):
    """Base of the generated processes: ports and Vars made from a ``Plan``."""

    def __init__(self, plan: Plan, **kwargs):
        super().__init__(plan=plan, name=plan.name, **kwargs)
        if plan.reads_events:
            setattr(self, CAMERA_PORT, InPort(shape=(plan.source_words,)))
        for port, lava_names in plan.inputs.items():
            for lava_name in lava_names:
                setattr(self, lava_name, InPort(shape=(plan.in_words[lava_name],)))
        for lava_name, words in plan.outputs.values():
            setattr(self, lava_name, OutPort(shape=(words,)))
        for var, (shape, _) in plan.vars.items():
            setattr(self, var, Var(shape=shape, init=0))
        self.tally = Var(shape=(max(len(plan.tally), 1),), init=0)


class PyTofnetModel(PyLoihiProcessModel):
    """Runs one tofnet model a step at a time (the generated subclasses declare the port types)."""

    def __init__(self, proc_params):
        super().__init__(proc_params)
        self.plan: Plan = proc_params["plan"]
        self.model = self.plan.model
        self.held: dict[str, np.ndarray] = {}  # what arrived in the previous step, per tofnet input
        self.buffers = {port: np.zeros(words, np.int64) for port, (_, words) in self.plan.outputs.items()}
        self.failed = False

    def run_spk(self) -> None:
        plan, k = self.plan, self.time_step - 1
        # every message of the step is taken and every port sends, whatever happens: a process that
        # stopped sending would leave Lava's runtime waiting for ever (it does not stop on an error)
        camera = getattr(self, CAMERA_PORT).recv() if plan.reads_events else None
        messages = {port: [getattr(self, n).recv() for n in names] for port, names in plan.inputs.items()}
        sent: dict[str, np.ndarray] = {}
        if not self.failed:
            try:
                sent = self._step(k, camera, messages)
            except Exception as err:  # reported to the host, which raises it after the run
                self.failed = True
                what = str(err) if isinstance(err, TofnetError) else f"{type(err).__name__}: {err}"
                plan.failures.report(f"process {plan.name!r} failed in step {k}: {what}")
        for port, (lava_name, words) in plan.outputs.items():
            message = sent.get(port)
            if message is None:
                message = self.buffers[port]
                message[0] = 0
            getattr(self, lava_name).send(message)

    def _step(self, k: int, camera, messages: dict[str, list[np.ndarray]]) -> dict[str, np.ndarray]:
        plan = self.plan
        if camera is not None:
            self.model.feed(unpack(camera, EVENT_DTYPE))
        received = {}
        for port, parts in messages.items():
            parts = [unpack(m, plan.dtypes[port]) for m in parts]
            received[port] = parts[0] if len(parts) == 1 else canonical(concat(parts, plan.dtypes[port]))
        inputs = {port: self.held.get(port, received[port][:0]) for port in plan.inputs}
        self.held = received  # runs next step: the connection's one-step delay
        sent = self.model.run(k, k + 1, inputs)
        out = {}
        for port, (_, words) in plan.outputs.items():
            records = sent.get(port)
            records = plan_empty(plan, port) if records is None else canonical(records)
            out[port] = pack(records, words, f"{plan.name}.{port}", self.buffers[port])
        return out

    # Var.get and Var.set reach the tofnet model: its state is read when asked for, not every step.
    def _get_var(self) -> None:
        name = self.var_id_to_var_map[int(self.service_to_process.peek()[0].item())]
        if name == "tally":
            counts = self.model.counts()
            self.tally = np.array([counts.get(key, 0) for key in self.plan.tally] or [0], np.int64)
        elif name in self.plan.vars:
            setattr(self, name, np.asarray(self.model.get_var(name, self.time_step), np.float64))
        super()._get_var()

    def _set_var(self) -> None:
        name = self.var_id_to_var_map[int(self.service_to_process.peek()[0].item())]
        if name in self.plan.vars:
            setattr(self, name, np.asarray(self.model.get_var(name, self.time_step), np.float64))
        super()._set_var()
        if name in self.plan.vars:
            shape, dtype = self.plan.vars[name]
            self.model.set_var(name, np.asarray(getattr(self, name)).astype(dtype).reshape(shape), self.time_step)


def plan_empty(plan: Plan, port: str) -> np.ndarray:
    return np.empty(0, plan.dtypes[port])


def process_for(plan: Plan, family: str) -> tuple[AbstractProcess, type]:
    """A Lava process for ``plan`` and its process model, both classes generated for it."""
    proc_cls = type(f"Lava{type(plan.model.process).__name__}", (TofnetLavaProcess,), {})
    ports: dict[str, Any] = {}
    if plan.reads_events:
        ports[CAMERA_PORT] = (PyInPort, LavaPyType(PyInPort.VEC_DENSE, np.int64))
    for lava_names in plan.inputs.values():
        ports.update({n: (PyInPort, LavaPyType(PyInPort.VEC_DENSE, np.int64)) for n in lava_names})
    for lava_name, _ in plan.outputs.values():
        ports[lava_name] = (PyOutPort, LavaPyType(PyOutPort.VEC_DENSE, np.int64))
    for var in list(plan.vars) + ["tally"]:
        ports[var] = (np.ndarray, LavaPyType(np.ndarray, np.float64))
    attrs = {name: lava_type for name, (_, lava_type) in ports.items()}
    attrs["__annotations__"] = {name: kind for name, (kind, _) in ports.items()}
    model_cls = type(f"Py{proc_cls.__name__}Model", (PyTofnetModel,), attrs)
    model_cls = implements(proc=proc_cls, protocol=LoihiProtocol)(requires(CPU)(tag(TAGS[family])(model_cls)))
    return proc_cls(plan), model_cls


def new_queue():
    """A queue the Lava runtime's forked processes inherit (host <-> source and sinks)."""
    return multiprocessing.get_context("fork").Queue()


class Failures:
    """Errors of the Lava processes, for the host: a shared flag (seen at once) and their messages."""

    def __init__(self):
        context = multiprocessing.get_context("fork")
        self.flag = context.Value("i", 0)
        self.messages = context.Queue()

    def report(self, message: str) -> None:
        self.messages.put(message)
        with self.flag.get_lock():
            self.flag.value += 1

    def first(self, timeout_s: float = 10.0) -> str | None:
        """The first error reported (None when none was)."""
        if not self.flag.value:
            return None
        try:
            return self.messages.get(timeout=timeout_s)
        except Exception:
            return "a Lava process failed (its message was lost)"
