"""What a model may send, checked where models run (the executor, band threads, worker processes).

A model's ``run`` (or ``StepModel.step``) returns a mapping of its declared output ports to
records laid out as the port's payload (``Payload.dtype``, 1-D), spikes at pixels inside the
process's size. A model that breaks this, or raises, stops the run with one line naming the
process, its model, the step and what was expected (docs/extending.md, "What a model may send"),
the same on every backend: before, a spike outside the sensor wrapped into the next row on
``fixed``, vanished on ``multiproc`` and was an ``IndexError`` on ``reference``. The model's own
exception stays the ``__cause__``.
"""

from __future__ import annotations

import os
import sysconfig
import traceback
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np

from tofnet.core.process import Process
from tofnet.errors import BackendError, TofnetError, interrupted, quote, reason, shown_path

#: Folders of the standard library, numpy and numba: a failure's place is the innermost frame outside them
#: (the model's own line, not numpy's).
_LIBRARIES = tuple(os.path.realpath(p) + os.sep for p in (sysconfig.get_paths()["stdlib"],
                                                         os.path.dirname(np.__file__),
                                                         os.path.dirname(numba.__file__)))


def who(process: Process, model_class: type) -> str:
    """How errors name a process and the model running it: ``process 'f' (FaultyModel)``."""
    return f"process {process.name!r} ({model_class.__name__})"


def steps_text(first: int, end: int) -> str:
    """``step 21`` or ``steps 0..202``: the steps a call to ``run(first, end, ...)`` simulated."""
    return f"step {first}" if end - first == 1 else f"steps {first}..{end - 1}"


def model_failed(name: str, steps: str, err: Exception) -> BackendError:
    """One line for a model's own exception: who, when, the exception and where in the model's code."""
    frames = traceback.extract_tb(err.__traceback__)
    ours = [f for f in frames if not os.path.realpath(f.filename).startswith(_LIBRARIES)]
    place = f" (at {shown_path(ours[-1].filename)}:{ours[-1].lineno})" if ours else ""
    what = type(err).__name__ + (f": {reason(err, 200)}" if str(err).strip() else "")
    return BackendError(f"{name}, {steps}: {what}{place}")


def checked_outputs(name: str, process: Process, sent: Any, steps: str,
                    dtypes: Mapping[str, np.dtype] | None = None) -> Mapping[str, Any]:
    """``sent`` when it is a mapping of declared output ports to records of each port's payload (or None);
    else one line saying what was expected. ``dtypes``: each port's record dtype, when already known."""
    ports = [spec.name for spec in process.outports]
    if not isinstance(sent, Mapping):
        raise BackendError(f"{name}, {steps}: returned {_kind(sent)}, expected a mapping of output port -> "
                           f"records (its ports: {', '.join(ports) or 'none'})")
    for port, records in sent.items():
        if port not in ports:
            shown = str(port) if str(port).isprintable() else quote(port)
            raise BackendError(f"{name}, {steps}: sent records on {process.name}.{shown:.40}, which it does not "
                               f"declare (its output ports: {', '.join(ports) or 'none'})")
        if records is None:
            continue
        dtype = dtypes[port] if dtypes is not None else process.port(port).spec.payload.dtype
        if not isinstance(records, np.ndarray) or records.dtype != dtype or records.ndim != 1:
            payload = process.port(port).spec.payload.name
            raise BackendError(f"{name}, {steps}: sent {_kind(records)} on {process.name}.{port}, expected a 1-D "
                               f"array of {payload} records ({_fields(dtype)}: the port's Payload.dtype)")
    return sent


def check_within(name: str, process: Process, port: str, records: np.ndarray, steps: str) -> None:
    """Raise when spike ``records`` sent on ``port`` in ``steps`` (``steps_text``) lie outside the process's
    size (vectorised: the coordinates' extremes first, the offending spikes only when there are some)."""
    if not len(records) or records.dtype.names is None or "x" not in records.dtype.names:
        return
    width, height = process.sensor_size
    x, y = records["x"], records["y"]
    signed = x.dtype.kind != "u" or y.dtype.kind != "u"
    if x.max() < width and y.max() < height and not (signed and (x.min() < 0 or y.min() < 0)):
        return
    bad = ~((x >= 0) & (x < width) & (y >= 0) & (y < height))  # a NaN coordinate too
    outside = records[bad]
    first = outside[np.lexsort((outside["x"], outside["y"], outside["step"]))[0]]  # first in the canonical order
    raise BackendError(f"{name} sent {len(outside):,} spikes on {process.name}.{port} outside its {width}x{height} "
                       f"size in {steps} (first x={first['x']}, y={first['y']} at step {first['step']}); a model's "
                       "spikes must lie within its port's size")


def run_model(process: Process, model, first: int, end: int, inputs: dict[str, np.ndarray],
              name: str | None = None) -> Mapping[str, Any]:
    """``model.run(first, end, inputs)`` for ``process``: its exception as one line naming the process, its model
    and the steps (a ``TofnetError`` is one line already: raised as it is), and what it returns checked
    (``checked_outputs``). ``name``: how to name it (``who``), when ``model`` stands in for one running elsewhere."""
    name, steps = name or who(process, type(model)), steps_text(first, end)
    with failures_named(name, steps):
        sent = model.run(first, end, inputs)
    return checked_outputs(name, process, sent, steps)


class failures_named:
    """``with failures_named(name, steps):`` a model's exception in the block becomes ``model_failed``'s one line,
    the exception its cause; a ``TofnetError`` (one line already) and an interrupt pass as they are."""

    def __init__(self, name: str, steps: str):
        self.name, self.steps = name, steps

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, err, tb) -> bool:
        # Ctrl-C inside a kernel arrives as a SystemError: the run was stopped, nothing failed
        if isinstance(err, Exception) and not isinstance(err, TofnetError) and not interrupted(err):
            raise model_failed(self.name, self.steps, err) from err
        return False


def _kind(value: Any) -> str:
    """What a value is, for an error: ``a list``, ``a float64 array of shape (3,)``, ``records (x, y)``."""
    if isinstance(value, np.ndarray):
        if value.dtype.names:
            return f"records ({_fields(value.dtype)}) of shape {value.shape}"
        return f"a {value.dtype} array of shape {value.shape}"
    article = "an" if type(value).__name__[:1].lower() in "aeiou" else "a"
    return f"{article} {type(value).__name__}"


def _fields(dtype: np.dtype) -> str:
    """``step <i8, x <u2, ...``: a record layout's fields and their types."""
    return ", ".join(f"{n} {dtype.fields[n][0].str}" for n in dtype.names)
