"""Write your own process: a depth-consistency filter, plugged into the paper's network.

Run: ``python examples/custom_process.py`` (about 20 s; ``--duration 0.1`` for a quick
look). It walks through docs/extending.md:

1. declare a process (ports, parameters with units, resources, placement);
2. give it a model and register it for every backend family;
3. compose it with tofnet's processes, in Python and in YAML;
4. run it on a simulated scene and score both outputs against the ground truth;
5. check that every backend runs it the same (a conformance check of its model).
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

from tofnet import DepthProcess, InputProcess, Network, Param, Payload, PortSpec, Process, TimeOfTravelProcess, \
    VelocityProcess
from tofnet.models import StepModel, model


# 1. The declaration: what the process is. No execution code here.
class DepthConsistencyProcess(Process):
    """Keeps a depth estimate only when a neighbour agrees with it.

    An estimate at pixel p in step k goes on when another pixel within ``radius`` px
    sent an estimate in steps ``k - window .. k`` that differs from it by at most
    ``tolerance`` (relative). Isolated outliers, the speckle of single bad time-of-travel
    measurements, are dropped and counted as ``inconsistent``.
    """

    inports = (PortSpec("depth", Payload.DEPTH, 1, "depth estimates, metres"),)
    outports = (PortSpec("kept", Payload.DEPTH, 1, "the estimates a neighbour agrees with"),)
    params = (
        Param("radius", "int", 2, unit="px", doc="neighbourhood that may agree", minimum=1),
        Param("window", "duration", "20ms", unit="s", doc="how recent the agreeing estimate must be", minimum=0.0),
        Param("tolerance", "float", 0.15, doc="largest relative difference that counts as agreement", minimum=0.0),
    )
    placement = "host"  # runs off-chip, like the input and velocity processes


# 2. The model: how it runs. A StepModel is called once per step with what arrived in it.
@model(DepthConsistencyProcess)  # the same model for the reference, float and fixed backends
class DepthConsistencyModel(StepModel):
    def __init__(self, process, ctx):
        super().__init__(process, ctx)
        width, height = ctx.sensor_size
        self.last_step = np.full((height, width), -(1 << 40), dtype=np.int64)  # when each pixel last estimated
        self.last_z = np.zeros((height, width))
        self.window = round(process.window * 1e6 / ctx.timestep_us)  # seconds -> whole steps
        self.kept = self.inconsistent = 0

    def step(self, k, inbox):
        estimates = inbox.get("depth")
        if estimates is None:
            return {"kept": None}
        x, y, z = estimates["x"].astype(np.int64), estimates["y"].astype(np.int64), estimates["z"]
        self.last_step[y, x], self.last_z[y, x] = k, z  # this step's estimates count as neighbours too
        height, width = self.last_z.shape
        agreed = np.zeros(len(estimates), dtype=bool)
        r = self.process.radius
        for dv in range(-r, r + 1):
            for du in range(-r, r + 1):
                if du == 0 and dv == 0:
                    continue
                nx, ny = np.clip(x + du, 0, width - 1), np.clip(y + dv, 0, height - 1)
                inside = (nx == x + du) & (ny == y + dv)
                recent = self.last_step[ny, nx] >= k - self.window
                close = np.abs(self.last_z[ny, nx] - z) <= self.process.tolerance * z
                agreed |= inside & recent & close
        self.kept += int(agreed.sum())
        self.inconsistent += int((~agreed).sum())
        kept = np.array(estimates[agreed])
        kept["t"] = self.ctx.t0_us + (k + 1) * self.ctx.timestep_us  # stamped with the end of the step it is sent in
        return {"kept": kept}

    def counts(self):
        return {"kept": self.kept, "inconsistent": self.inconsistent}


# 3. Composition, in Python ...
def network(sensor_size=(240, 180)) -> Network:
    inp = InputProcess(name="input", sensor_size=sensor_size)
    tot = TimeOfTravelProcess(name="time_of_travel")
    depth = DepthProcess(name="depth")
    velocity = VelocityProcess(name="velocity")
    consistent = DepthConsistencyProcess(name="consistent")
    inp.events.connect(tot.events)
    tot.counts.connect(depth.counts)
    velocity.a_t.connect(depth.a_t)
    depth.depth.connect(consistent.depth)
    return Network([inp, tot, depth, velocity, consistent], name="consistent-depth")


# ... and in YAML: a class defined by a script is known by its name once the script ran;
# from a package, write type: my_package.my_module:DepthConsistencyProcess.
SPEC = """
name: consistent-depth
processes:
  input: {type: InputProcess, sensor_size: [240, 180]}
  time_of_travel: {type: TimeOfTravelProcess}
  depth: {type: DepthProcess}
  velocity: {type: VelocityProcess}
  consistent: {type: DepthConsistencyProcess, radius: 2, window: 20ms, tolerance: 0.15}
connections:
  - input.events -> time_of_travel.events
  - time_of_travel.counts -> depth.counts
  - velocity.a_t -> depth.a_t
  - depth.depth -> consistent.depth
"""


def main(duration: float) -> None:
    from tofnet.api import run
    from tofnet.conformance.compare import compare
    from tofnet.eval.metrics import evaluate
    from tofnet.io import read_recording
    from tofnet.io.spec import load_spec, networks_equal
    from tofnet.sim.run import simulate

    net = network()
    assert networks_equal(load_spec(SPEC).network, net), "the YAML spec and the Python network differ"

    # 4. Run on a simulated scene; the network has two depth outputs: before and after the filter.
    with tempfile.TemporaryDirectory() as folder:
        simulate("slider", folder, duration=duration, seed=0)
        recording = read_recording(folder)
    result, _ = run(recording, net, backend="fixed", probes=["depth.depth"])  # the filter's input too
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us}
    print(f"{'output':<18} {'estimates':>9} {'coverage':>9} {'median rel':>10} {'mean rel':>9}")
    for name in ("depth.depth", "consistent.kept"):
        scored = evaluate(recording, result.outputs[name], {**meta, "latency_steps": result.latency[name]})
        print(f"{name:<18} {scored.estimates:>9,} {scored.coverage:>9.1%} {scored.errors.median_rel_pct:>9.1f}% "
              f"{scored.errors.mean_rel_pct:>8.1f}%")
    print(f"counts of 'consistent': {result.counts['consistent']}")

    # 5. A conformance check of the model: backends of one arithmetic give the same bytes.
    #    Between float and fixed arithmetic the depths differ by the quantisation bound, so an
    #    estimate near the tolerance may be kept by one and not the other: compare() only
    #    states a bound for the depth process and lists the rest in its notes.
    runs = {name: run(recording, net, backend=name, probes=["depth.depth"])[0]
            for name in ("reference", "float", "multiproc")}
    runs["fixed"] = result
    for a, b, mode in (("multiproc", "fixed", "exact"), ("float", "reference", "float"),
                       ("fixed", "reference", "quantised")):
        comparison = compare(runs[a], runs[b], mode, net)
        print(f"{a} vs {b} ({mode}): {'same' if comparison.ok else 'DIFFERENT: ' + comparison.first}")
        for note in comparison.notes:
            print(f"    note: {note}")
        assert comparison.ok


if __name__ == "__main__":  # the multiproc backend spawns workers that import this file
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=0.5, help="seconds of simulated motion")
    main(parser.parse_args().duration)
