"""What every figure shares: its size and resolution, the depth colours, an Agg canvas, the window.

Depths are in metres, times in seconds since the run's ``t0``.
"""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from tofnet.eval.views import Window, resolve_window, sensor_size_of, time_span_us, widened_window

#: Pixels per inch of the PNGs.
DPI = 120
#: Figure size in inches per kind (PNG size = size * DPI).
FIGURE_SIZES = {"depthmap": (12.0, 4.8), "depthmap_single": (7.0, 4.8), "histogram": (8.0, 4.8),
                "error": (10.0, 8.5), "cloud": (15.0, 7.0), "compare": (16.0, 8.5)}
#: Depth colours: turbo reversed (near is red, far is blue), without its two darkest
#: ends so every depth stands out against the dark background of empty pixels.
DEPTH_CMAP = matplotlib.colors.ListedColormap(matplotlib.colormaps["turbo"](np.linspace(0.92, 0.08, 256)),
                                             name="tofnet_depth")
#: Background of pixels without a depth.
EMPTY_COLOUR = "#1a1a1a"


def span_us(recording, depth: np.ndarray, meta: dict) -> tuple[int, int]:
    """``[t0, end)`` (µs) covering the recording's events and the estimates."""
    return time_span_us(recording.events, depth, int(meta["t0_us"]))


def figure_window(window, recording, depth: np.ndarray, meta: dict, default_s: float | None) -> Window:
    """``window`` as a ``Window``: kept when it is one, else resolved (``resolve_window``). A default window
    (none asked for) holding fewer than ``max(500, 2 % of the sensor's pixels)`` estimates is widened
    (``widened_window``) and says so in its label."""
    if isinstance(window, Window):
        return window
    span = span_us(recording, depth, meta)
    resolved = resolve_window(window, span, default_s=default_s)
    if window is not None and window != "":
        return resolved
    width, height = sensor_size_of(recording, depth)
    return widened_window(resolved, span, depth["t"], max(500, width * height // 50))


def new_figure(kind: str) -> Figure:
    """An empty figure of ``FIGURE_SIZES[kind]`` drawn by Agg, whatever backend pyplot uses."""
    fig = Figure(figsize=FIGURE_SIZES[kind], dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def depth_cmap():
    """``DEPTH_CMAP`` with NaN (no depth) drawn in ``EMPTY_COLOUR``."""
    return DEPTH_CMAP.with_extremes(bad=EMPTY_COLOUR)
