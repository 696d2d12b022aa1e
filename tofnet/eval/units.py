"""Time-of-travel units at work (the paper's Fig. 2, from a real run): counters, spikes in and out, depth.

``unit_traces`` runs a network in a ``Session`` up to a window and records, at chosen pixels,
the four units' counters every step, the input spikes that trigger them (at the pixel) and
facilitate them (``distance`` pixels back along each direction), the counts they send and
the depth estimates; ``units_figure`` draws one panel per pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofnet.errors import TofnetError
from tofnet.events import DIRECTION_OFFSETS, DIRECTIONS

COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red")


@dataclass
class UnitTraces:
    """What ``unit_traces`` recorded; steps are absolute, ``t0_us``/``timestep_us`` convert them."""

    pixels: list[tuple[int, int]]
    distance: int
    steps: np.ndarray  # [samples]
    counters: np.ndarray  # [samples, 4, pixels], steps
    inputs: np.ndarray  # input spikes at the pixels and their facilitators (step, x, y, p)
    counts: np.ndarray  # counter spikes sent at the pixels
    depth: np.ndarray  # estimates at the pixels (DEPTH_DTYPE)
    t0_us: int
    timestep_us: int


def unit_traces(recording, network, pixels: list[tuple[int, int]], start_s: float, end_s: float, *,
                input_name: str = "input", units_name: str = "time_of_travel", depth_name: str = "depth",
                backend: str = "fixed") -> UnitTraces:
    """Run ``network`` on ``recording`` to ``start_s`` (s after step 0), then record to ``end_s``."""
    from tofnet.monitor import Monitor
    from tofnet.session import Session

    if not end_s > start_s >= 0:
        raise TofnetError(f"window: expected 0 <= start < end seconds, got {start_s:g}..{end_s:g}")
    units = network.process(units_name)
    width, height = units.sensor_size
    for x, y in pixels:
        if not (0 <= x < width and 0 <= y < height):
            raise TofnetError(f"pixel {x},{y} is outside the {width}x{height} sensor")
    d = int(units.distance)
    around = sorted({(x - d * du, y - d * dv) for x, y in pixels for du, dv in DIRECTION_OFFSETS} | set(pixels))
    with Session(network, recording, backend=backend,
                 probes=[f"{input_name}.events", f"{units_name}.counts", f"{depth_name}.depth"]) as session:
        session.run(until=start_s)
        first = session.step
        counter = Monitor(f"{units_name}.counter", pixels=list(pixels))
        inputs = Monitor(f"{input_name}.events", pixels=around)
        sent = Monitor(f"{units_name}.counts", pixels=list(pixels))
        depth = Monitor(f"{depth_name}.depth", pixels=list(pixels))
        session.add_monitors([counter, inputs, sent, depth])
        session.run(until=end_s)
        t0_us, dt = session.stream.t0_us, session.timestep_us
    empty = np.empty(0)
    return UnitTraces(list(pixels), d, np.asarray(counter.steps), counter.values, inputs.values if inputs._values
                      else empty, sent.values if sent._values else empty, depth.values if depth._values else empty,
                      t0_us, dt)


def units_figure(traces: UnitTraces):
    """One panel per pixel: the four counters over time (ms), with the spikes and the depth."""
    from matplotlib.figure import Figure

    n = len(traces.pixels)
    fig = Figure(figsize=(9, 2.6 * n + 0.6), layout="constrained")
    axes = fig.subplots(n, 1, squeeze=False, sharex=True)[:, 0]
    ms = traces.timestep_us * 1e-3
    for i, (ax, (x, y)) in enumerate(zip(axes, traces.pixels)):
        for c, (name, colour) in enumerate(zip(DIRECTIONS, COLOURS)):
            ax.step(traces.steps * ms, traces.counters[:, c, i], where="post", color=colour, label=f"unit {name}")
            du, dv = DIRECTION_OFFSETS[c]
            fx, fy = x - traces.distance * du, y - traces.distance * dv
            if traces.inputs.size:
                at = traces.inputs[(traces.inputs["x"] == fx) & (traces.inputs["y"] == fy)]
                ax.plot(at["step"] * ms, np.zeros(len(at)), "^", color=colour, ms=7,
                        label="facilitating spike" if c == 0 else None)
        if traces.inputs.size:
            trig = traces.inputs[(traces.inputs["x"] == x) & (traces.inputs["y"] == y)]
            for k, s in enumerate(trig["step"]):
                ax.axvline(s * ms, color="black", lw=0.8, ls=":", label="trigger spike" if k == 0 else None)
        if traces.counts.size:
            out = traces.counts[(traces.counts["x"] == x) & (traces.counts["y"] == y)]
            ax.plot(out["step"] * ms, out["count"], "o", mfc="none", color="black", label="count sent")
        if traces.depth.size:
            est = traces.depth[(traces.depth["x"] == x) & (traces.depth["y"] == y)]
            if len(est):
                twin = ax.twinx()
                twin.plot(est["step"] * ms, est["z"], "D", color="tab:purple", label="depth estimate")
                twin.set_ylabel("depth [m]", color="tab:purple")
                twin.set_ylim(0, max(float(est["z"].max()) * 1.3, 0.1))
        ax.set_ylabel("counter [steps]")
        ax.set_title(f"pixel ({x}, {y}): the four time-of-travel units")
        if i == 0:
            ax.legend(loc="upper left", fontsize=7, ncol=4)
    axes[-1].set_xlabel(f"time since step 0 [ms] (1 step = {ms:g} ms)")
    return fig
