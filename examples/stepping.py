# %% [markdown]
# # Stepping through the paper's network
#
# A walk for newcomers, cell by cell (`# %%` cells run in VS Code, Jupyter via jupytext, or
# as a plain script: `python examples/stepping.py`, about 15 s). We simulate a camera
# sliding past a desk, run the paper's network a few steps at a time, look inside the
# time-of-travel units between runs, change a parameter on the way and draw the units at
# work (the paper's Fig. 2). Lava users: `Session.run(steps=n)` is `proc.run(RunSteps(n))`,
# `Session.get`/`set` are `Var.get`/`set`, `Monitor` is Lava's `Monitor`
# (docs/sessions.md has the table).

# %%
import tempfile
from pathlib import Path

import numpy as np

from tofnet import Monitor, Session, depth_network
from tofnet.eval.units import unit_traces, units_figure
from tofnet.io import read_recording
from tofnet.sim.run import simulate

workspace = tempfile.TemporaryDirectory(prefix="tofnet-stepping-")  # removed at the end (or at exit)
folder = Path(workspace.name) / "slider"
simulate("slider", folder, duration=0.3, seed=0)  # events, poses, calibration, true depth
recording = read_recording(folder)
network = depth_network(recording.sensor_size)  # input -> time_of_travel -> depth <- velocity
print(f"{len(recording.events):,} events over {recording.duration:.2f} s on a {recording.sensor_size} sensor")

# %% [markdown]
# ## Open a session and run 50 steps
# Every step is 1 ms. Each connection delays by one step: an event in step k reaches the
# units in step k+1 and its depth comes out in step k+2.

# %%
session = Session(network, recording, backend="fixed",
                  monitors=[Monitor("time_of_travel.counter", pixels=[(120, 90)])])
out = session.run(steps=50)
print(f"after step {session.step - 1}: {len(out['depth.depth']):,} depth estimates so far")

# %% [markdown]
# ## Look inside: the counters of the time-of-travel units
# `time_of_travel.counter` is `[4, height, width]`: the count each unit (+u, -u, +v, -v)
# shows at the start of the current step (0 = idle). The fixed backend stores facilitation
# times instead of counters; every backend reports the same counters.

# %%
counter = session.get("time_of_travel.counter")
running = counter > 0
print(f"{running.sum():,} units are counting; the longest count is {counter.max()} steps")
print("unit counters at pixel (120, 90):", counter[:, 90, 120])

# %% [markdown]
# ## Change a parameter mid-recording, then run on
# Events fed from now on are filtered with the new refractory period; the session works on
# its own copy of the network.

# %%
session.set("input.refractory", "20ms")
session.run(until=0.2)  # to 200 ms after step 0
print(f"step {session.step}: input counts {session.counts()['input']}")

# %% [markdown]
# ## Finish: the rest of the recording, and the whole run's result

# %%
result = session.finish()
print(f"{len(result.depth):,} estimates; median depth {np.median(result.depth['z']):.2f} m")
monitor = session.monitors[0]
print(f"the monitor sampled pixel (120, 90) {len(monitor.steps)} times: values {monitor.values.shape}")

# %% [markdown]
# ## The units at work (paper Fig. 2)
# Counters ramp after a facilitating spike (triangles), a trigger (dotted line) makes them
# send their count (circles) and the depth neuron turns the counts into a depth (diamond).
# The figure goes to the current folder; the simulated recording is removed.

# %%
traces = unit_traces(recording, depth_network(recording.sensor_size), [(120, 90)], 0.08, 0.14)
figure = units_figure(traces)
path = Path("stepping_units.png")
figure.savefig(path, dpi=120)
print(f"figure: {path.resolve()}")
workspace.cleanup()
