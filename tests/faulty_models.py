"""A user's process whose model breaks the contract of docs/extending.md in a chosen way (``mode``).

In a module of its own so that ``multiproc``'s spawned workers import it as a user's package would be.
"""

import numpy as np

from tofnet import Network, Param, Payload, PortSpec, Process
from tofnet.models import Model, StepModel, model
from tofnet.processes import DepthProcess, InputProcess, TimeOfTravelProcess, VelocityProcess

#: The step from which ``raise`` raises (its first steps run well).
RAISE_FROM = 20


class FaultyProcess(Process):
    """Passes its spikes on, or breaks the contract as ``mode`` says."""

    inports = (PortSpec("events", Payload.POLARITY, 1, "spikes"),)
    outports = (PortSpec("passed", Payload.POLARITY, 1, "spikes"),)
    params = (Param("mode", "str", "ok", doc="ok, shift (x + width), raise, interrupt, port, dtype, list or float"),)
    resources_per_pixel = {"accumulators": 1}


@model(FaultyProcess)
class FaultyModel(StepModel):
    supports_regions = True  # it sends only what it is given: on a core, its region's spikes

    def step(self, k, inbox):
        spikes = inbox.get("events")
        if spikes is None:
            return {"passed": None}
        mode = self.process.mode
        if mode == "shift":  # one sensor width to the right: into the next row of a flat index
            out = np.array(spikes)
            out["x"] += self.ctx.sensor_size[0]
            return {"passed": out}
        if mode == "raise" and k > RAISE_FROM:
            raise ValueError("boom in my model")
        if mode == "interrupt":  # Ctrl-C inside a numba kernel reaches Python as a SystemError
            raise SystemError("interrupted in a kernel") from KeyboardInterrupt()
        if mode == "port":
            return {"pased": spikes}
        if mode == "dtype":
            return {"passed": np.zeros(len(spikes), dtype=[("x", "<i4"), ("y", "<i4")])}
        if mode == "list":
            return [spikes]
        if mode == "float":
            return {"passed": np.ones(len(spikes))}
        return {"passed": spikes}


class FaultyRangeProcess(FaultyProcess):
    """The same faults from a model run over ranges of steps (``Model.run``)."""


@model(FaultyRangeProcess)
class FaultyRangeModel(Model):
    supports_regions = True

    def run(self, first, end, inputs):
        spikes = np.array(inputs["events"])
        mode = self.process.mode
        if mode == "shift":
            spikes["x"] += self.ctx.sensor_size[0]
        if mode == "raise":
            raise ValueError("boom in my model")
        if mode == "dtype":
            return {"passed": spikes[["x", "y"]]}
        if mode == "port":
            return {"pased": spikes}
        spikes["step"] += 1  # what arrived in step k-1 is sent in step k
        return {"passed": spikes}


def faulty_network(sensor_size, mode: str, *, kind=FaultyProcess) -> Network:
    """input -> f (faulty) -> time of travel -> depth <- velocity: the paper's chain behind a user's process."""
    inp = InputProcess(name="input", sensor_size=sensor_size, refractory=0)
    faulty = kind(name="f", mode=mode)
    tot, dep = TimeOfTravelProcess(name="time_of_travel"), DepthProcess(name="depth")
    vel = VelocityProcess(name="velocity", source="constant", velocity=[-0.5, 0.2, 0.1], per="pixel")
    inp.events.connect(faulty.events)
    faulty.passed.connect(tot.events)
    tot.counts.connect(dep.counts)
    vel.a_t.connect(dep.a_t)
    return Network([inp, faulty, tot, dep, vel])
