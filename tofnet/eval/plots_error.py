"""The error over time (after the paper's Fig. 3): camera motion and the windowed relative error.

Depths are in metres, times in seconds since the run's ``t0``.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from tofnet.eval.bins import band_window_s, window_quartiles
from tofnet.eval.metrics import evaluate
from tofnet.eval.plots_base import new_figure, span_us
from tofnet.eval.views import has_poses, poses_at
from tofnet.units import MAX_METRIC_WINDOWS, bounded_windows, format_seconds

#: One style per axis, so lines that coincide (a slider's y and z, both 0) stay apart:
#: colour, line style, marker; the markers of y and z sit at alternate places.
AXIS_STYLES = {"x": dict(color="tab:red", linestyle="-", linewidth=1.8),
               "y": dict(color="tab:green", linestyle="--", linewidth=1.8, marker="o", markersize=4,
                         markevery=(0, 60)),
               "z": dict(color="tab:blue", linestyle=":", linewidth=2.4, marker="^", markersize=5,
                         markevery=(30, 60))}
#: A window with fewer matched estimates than this is left out of the band (its quartiles would be noise).
LEAST_PER_WINDOW = 10
#: The band's median gets a marker per window up to this many windows.
MARKED_WINDOWS = 30


def error_figure(recording, depth: np.ndarray, meta: dict, *, window_s: float | None = None) -> Figure:
    """Camera motion and the windowed relative error over time (paper Fig. 3).

    Top: camera position in the world (``poses_at``); middle: camera-frame velocity
    (the quantity the network uses; error grows with motion along z); bottom: median
    relative error per ``window_s`` window with its interquartile band. ``window_s``
    None: from the data (``band_window_s``: about 200 matched estimates per window, at
    most 100 windows, a round number of timesteps).
    """
    ev = evaluate(recording, depth, meta, window_s=0)
    t0_us = ev.t0_us
    start_us, end_us = span_us(recording, depth, meta)
    if window_s is None:
        window_s = band_window_s(ev.matched, (end_us - t0_us) * 1e-6, ev.timestep_us * 1e-6)
    traj = recording.trajectory
    rows = (["position"] if has_poses(traj) else []) + (["velocity"] if traj is not None else []) + ["error"]
    fig = new_figure("error")
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    t_grid = np.linspace(start_us, end_us, 600)
    t_rel = (t_grid - t0_us) * 1e-6
    for ax, row in zip(axes, rows):
        if row == "position":
            pos, _ = poses_at(traj, t_grid * 1e-6)
            for k, name in enumerate("xyz"):
                ax.plot(t_rel, pos[:, k], label=name, **AXIS_STYLES[name])
            ax.set_ylabel("position (world) [m]")
            ax.set_title("Camera trajectory")
        elif row == "velocity":
            vel = traj.velocity_at(t_grid * 1e-6)
            for k, name in enumerate("xyz"):
                ax.plot(t_rel, vel[:, k], label=f"$t_{name}$", **AXIS_STYLES[name])
            ax.axhline(0.0, color="0.6", linewidth=0.8)
            ax.set_ylabel("velocity (camera) [m/s]")
            ax.set_title("Camera velocity in the camera frame (z = optical axis)")
        else:
            _plot_error(ax, ev, depth["z"], window_s, end_us - t0_us)
        ax.grid(True, alpha=0.3)
        if row != "error":
            ax.legend(loc="best", ncols=3, fontsize="small", handlelength=3.5)
    axes[-1].set_xlabel("time since start [s]")
    axes[-1].set_xlim(0.0, (end_us - t0_us) * 1e-6)
    e = ev.errors
    overall = f"; overall mean {e.mean_rel_pct:.1f} %, median {e.median_rel_pct:.1f} %" if e.n else ""
    fig.suptitle(f"Relative depth error over time ({ev.matched:,} matched estimates{overall})")
    return fig


def _plot_error(ax, ev, z: np.ndarray, window_s: float, duration_us: int) -> None:
    """Median and interquartile relative error (%) per window, at window centres.

    An estimate counts in the window of its triggering input step (as in ``evaluate``).
    """
    m = ev.matches
    valid = m.valid
    rel = np.abs(z[valid] - m.gt[valid]) / m.gt[valid] * 100.0
    window_us = max(1, int(round(window_s * 1e6)))
    n = bounded_windows(max(1, -(-duration_us // window_us)), window_us, f"the error bands over "
                        f"{format_seconds(duration_us * 1e-6)}", "give a longer --error-window (or auto)",
                        MAX_METRIC_WINDOWS)
    # A window longer than the span holds the same values; shortened to it, it stays inside int64 (an automatic
    # window for a 2**61 µs span is 200 times that).
    window_us = min(window_us, duration_us + 1)
    q, counts = window_quartiles(m.input_step[valid] * ev.timestep_us, rel, window_us, n,
                                 least=LEAST_PER_WINDOW)
    centres = (np.arange(n) + 0.5) * window_us * 1e-6
    ax.fill_between(centres, q[0], q[2], color="tab:purple", alpha=0.25, linewidth=0, label="25\u201375 %")
    ax.plot(centres, q[1], color="tab:purple", marker="." if n <= MARKED_WINDOWS else None, label="median")
    top = np.nanmax(q[2]) if np.isfinite(q[2]).any() else 1.0
    ax.set_ylim(0.0, top * 1.1)
    ax.set_ylabel("relative error [%]")
    shown = counts[counts >= LEAST_PER_WINDOW]
    typical = f", a median {int(np.median(shown)):,} estimates each" if len(shown) else ""
    ax.set_title(f"Relative depth error |z \u2212 z_gt| / z_gt per {format_seconds(window_s)} window "
                 f"({n} windows{typical})")
    ax.legend(loc="upper right", fontsize="small")
