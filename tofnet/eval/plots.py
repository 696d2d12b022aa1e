"""Figures of depth estimates, after the paper's Figures 1, 3, 4, 5 and 6.

Every function returns a ``matplotlib.figure.Figure`` on an Agg canvas, built without
pyplot: no display needed, and the caller's matplotlib backend is left alone.
``save_figure`` writes it as PNG.
Depths are in metres, times in seconds since the run's ``t0``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from tofnet.errors import DataError
from tofnet.eval.bins import histogram_edges
from tofnet.eval.match import match_estimates
from tofnet.eval.metrics import evaluate
from tofnet.eval.plots_base import (DEPTH_CMAP, DPI, EMPTY_COLOUR, FIGURE_SIZES, depth_cmap, figure_window,
                                    new_figure)
from tofnet.eval.plots_cloud import cloud_figure
from tofnet.eval.plots_error import error_figure
from tofnet.eval.views import depth_image, depth_range, has_poses, sensor_size_of

__all__ = ["DPI", "FIGURE_SIZES", "DEPTH_CMAP", "EMPTY_COLOUR", "KINDS", "depth_map_figure",
           "comparison_figure", "histogram_figure", "error_figure", "cloud_figure", "figure", "save_figure",
           "available_kinds", "plot_all"]

#: Default windows: the paper's Fig. 5 accumulates 70 ms; the others use the whole run.
DEPTHMAP_WINDOW_S = 0.07
KINDS = ("depthmap", "histogram", "error", "cloud")


def depth_map_figure(recording, depth: np.ndarray, meta: dict, *, window=None, reduce: str = "latest",
                     with_gt: bool = True) -> Figure:
    """Depth accumulated per pixel over a window (paper Fig. 5, 6), beside the ground truth.

    Each pixel shows its ``reduce`` (``"latest"`` or ``"median"``) depth in the window;
    pixels without one stay dark. The ground-truth panel (when the recording has
    ``gt_depth``) accumulates the true depth of the input events of the same window.
    ``window``: a ``Window``, a spec for ``resolve_window`` or None (70 ms, centred).
    """
    win = figure_window(window, recording, depth, meta, DEPTHMAP_WINDOW_S)
    size = sensor_size_of(recording, depth)
    sel = depth[win.contains(depth["t"])]
    images = [("Estimates", depth_image(sel["x"], sel["y"], sel["z"], sel["t"], size, reduce))]
    if with_gt and recording.gt_depth is not None:
        ev = recording.events
        keep = win.contains(ev["t"]) & np.isfinite(recording.gt_depth) & (recording.gt_depth > 0)
        images.append(("Ground truth of the input events",
                       depth_image(ev["x"][keep], ev["y"][keep], recording.gt_depth[keep], ev["t"][keep], size, reduce)))
    vmin, vmax = depth_range(*(image for _, image in images))
    kind = "depthmap" if len(images) == 2 else "depthmap_single"
    fig = new_figure(kind)
    axes = fig.subplots(1, len(images), squeeze=False)[0]
    for ax, (name, image) in zip(axes, images):
        shown = ax.imshow(image, cmap=depth_cmap(), vmin=vmin, vmax=vmax, interpolation="nearest", origin="upper")
        ax.set_facecolor(EMPTY_COLOUR)
        ax.set_title(f"{name} ({np.count_nonzero(np.isfinite(image)):,} px)")
        ax.set_xlabel("x [px]")
        ax.set_ylabel("y [px]")
    fig.colorbar(shown, ax=list(axes), label="depth [m]", shrink=0.9, extend="both")
    fig.suptitle(f"Depth accumulated over {win.label()} ({reduce} per pixel; {len(sel):,} estimates){win.note()}")
    return fig


def comparison_figure(recording, runs: dict[str, tuple[np.ndarray, dict]], *, window=None,
                      reduce: str = "latest") -> Figure:
    """Several estimators on the same events, side by side: their depth maps over one window
    (and the ground truth's) in one colour range, titled with each one's errors over the whole
    run, and below, the distribution of their signed relative errors.

    ``runs`` maps a label to ``(depth, meta)``; the ground truth needs ``recording.gt_depth``.
    """
    first_depth, first_meta = next(iter(runs.values()))
    win = figure_window(window, recording, first_depth, first_meta, DEPTHMAP_WINDOW_S)
    size = sensor_size_of(recording, first_depth)
    panels, errors = [], {}
    for label, (depth, meta) in runs.items():
        sel = depth[win.contains(depth["t"])]
        title = f"{label}\n{len(depth):,} estimates"
        if recording.gt_depth is not None:
            ev = evaluate(recording, depth, meta, window_s=0)
            m = ev.matches
            errors[label] = (depth["z"][m.valid] - m.gt[m.valid]) / m.gt[m.valid] * 100.0
            title += (f"\nmedian error {ev.errors.median_rel_pct:.1f} %, mean {ev.errors.mean_rel_pct:.1f} %, "
                      f"bias {ev.errors.bias_rel_pct:+.1f} %")
        panels.append((title, depth_image(sel["x"], sel["y"], sel["z"], sel["t"], size, reduce)))
    if recording.gt_depth is not None:
        events = recording.events
        keep = win.contains(events["t"]) & np.isfinite(recording.gt_depth) & (recording.gt_depth > 0)
        panels.append(("Ground truth of the input events\n\n", depth_image(
            events["x"][keep], events["y"][keep], recording.gt_depth[keep], events["t"][keep], size, reduce)))
    vmin, vmax = depth_range(*(image for _, image in panels))
    fig = new_figure("compare")
    grid = fig.add_gridspec(2 if errors else 1, len(panels), height_ratios=[3, 2] if errors else [1])
    for i, (title, image) in enumerate(panels):
        ax = fig.add_subplot(grid[0, i])
        shown = ax.imshow(image, cmap=depth_cmap(), vmin=vmin, vmax=vmax, interpolation="nearest", origin="upper")
        ax.set_facecolor(EMPTY_COLOUR)
        ax.set_title(title, fontsize="medium")
        ax.set_xlabel("x [px]")
    fig.colorbar(shown, ax=fig.axes, label="depth [m]", shrink=0.8, extend="both", location="right")
    if errors:
        ax = fig.add_subplot(grid[1, :])
        edges = np.linspace(-60.0, 60.0, 121)
        for label, rel in errors.items():
            ax.hist(np.clip(rel, edges[0], edges[-1]), bins=edges, histtype="step", linewidth=1.6,
                    label=f"{label} ({len(rel):,} matched)")
        ax.axvline(0.0, color="0.4", linewidth=0.8)
        ax.set_xlim(edges[0], edges[-1])
        ax.set_xlabel("signed relative error (z \u2212 z_gt) / z_gt [%] (beyond \u00b160 % in the end bins)")
        ax.set_ylabel("estimates per 1 % bin")
        ax.legend(loc="upper right", fontsize="small")
    fig.suptitle(f"The same events, two estimators: depth over {win.label()} ({reduce} per pixel); "
                 f"errors over the whole run{win.note()}")
    return fig


def histogram_figure(recording, depth: np.ndarray, meta: dict, *, window=None, with_gt: bool = True,
                     bins: int = 100) -> Figure:
    """Histogram of estimated depths (paper Fig. 4), over the ground truth of the same events.

    The overlay is the true depth of the events the estimates were matched to, so the
    two differ only by the estimation error (and the time discretisation it shows).
    Estimates that are whole counter steps (``histogram_edges``) are binned a whole
    number of steps per bin, and the figure says how large a step is.
    """
    win = figure_window(window, recording, depth, meta, None)
    inside = win.contains(depth["t"])
    z = depth["z"][inside]
    gt = np.empty(0)
    if with_gt and recording.gt_depth is not None:
        m = match_estimates(depth, recording.events, recording.gt_depth, t0_us=int(meta["t0_us"]),
                            timestep_us=int(meta["timestep_us"]), latency_steps=int(meta["latency_steps"]))
        gt = m.gt[inside & m.valid]
    edges, step, per_bin = histogram_edges(np.concatenate([z, gt]), z, bins)
    fig = new_figure("histogram")
    ax = fig.subplots()
    label = f"estimates ({len(z):,})"
    if step is not None:
        label = f"estimates ({len(z):,}), all whole multiples of {step:.3g} m"
    ax.hist(z, bins=edges, color="tab:blue", alpha=0.75, label=label)
    if len(gt):
        ax.hist(gt, bins=edges, histtype="step", color="black", linewidth=1.4,
                label=f"ground truth of the same events ({len(gt):,})")
    beyond = int(np.count_nonzero(z > edges[-1]))
    ax.set_xlim(0.0, edges[-1])
    ax.set_xlabel("depth [m]")
    width = edges[1] - edges[0]
    if step is None:
        ax.set_ylabel(f"estimates per {width:g} m bin")
    else:
        steps = f"{per_bin} counter step{'s' if per_bin > 1 else ''}"
        ax.set_ylabel(f"estimates per {width:.3g} m bin ({steps})")
        # Why the bins follow the steps: the time of travel is a whole number of timesteps.
        ax.text(0.99, 0.80, f"depth = n \u00d7 |A t| \u00d7 {meta['timestep_us'] / 1000:g} ms, n a whole number "
                f"(the time-of-travel counter):\none step is {step:.3g} m here; each bin holds {steps}, "
                "centred on them", transform=ax.transAxes, ha="right", va="top", fontsize="small", color="0.25")
    ax.legend(loc="upper right")
    note = f"\n({beyond:,} estimates beyond {edges[-1]:.2f} m not shown)" if beyond else ""
    ax.set_title(f"Depth histogram over {win.label()}{note}")
    return fig


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG at its own size (``DPI``), atomically; returns the path."""
    from tofnet.io.files import atomic_write
    path = Path(path)
    with atomic_write(path) as handle:
        fig.savefig(handle, dpi=DPI, format="png")
    return path


def figure(kind: str, recording, depth: np.ndarray, meta: dict, *, window=None,
           window_s: float | None = None, reduce: str = "latest", with_gt: bool = True) -> Figure:
    """The figure of one ``kind`` in ``KINDS``.

    ``window`` selects the time span (``resolve_window``; the error figure always
    covers the whole run), ``window_s`` the error figure's window length in seconds (None:
    chosen from the data), ``reduce`` the depth map's per-pixel rule, ``with_gt`` whether
    to draw ground truth.
    """
    if kind == "depthmap":
        return depth_map_figure(recording, depth, meta, window=window, reduce=reduce, with_gt=with_gt)
    if kind == "histogram":
        return histogram_figure(recording, depth, meta, window=window, with_gt=with_gt)
    if kind == "error":
        return error_figure(recording, depth, meta, window_s=window_s)
    if kind == "cloud":
        return cloud_figure(recording, depth, meta, window=window)
    raise DataError(f"unknown plot kind {kind!r}; choose from {', '.join(KINDS)}")


def available_kinds(recording) -> dict[str, str | None]:
    """Each kind mapped to None when the recording supports it, else the reason it does not."""
    return {"depthmap": None, "histogram": None,
            "error": None if recording.gt_depth is not None else
            "needs per-event ground-truth depth (events_depth.npy), e.g. from `tofnet simulate`",
            "cloud": _cloud_missing(recording)}


def _cloud_missing(recording) -> str | None:
    """What the 3D cloud lacks (it places the estimates in the world: the camera and its poses), or None."""
    missing = ([] if recording.intrinsics is not None else ["intrinsics (calib.txt, --intrinsics or --calib)"]) + \
        ([] if has_poses(recording.trajectory) else ["camera poses (groundtruth.txt)"])
    return f"needs {' and '.join(missing)}; the recording has none" if missing else None


def plot_all(recording, depth: np.ndarray, meta: dict, out_dir: str | Path, *, prefix: str = "",
             **options) -> list[Path]:
    """Write every figure the recording supports to ``out_dir/{prefix}{kind}.png``.

    ``options`` go to ``figure``. Kinds the recording cannot support (see
    ``available_kinds``) are skipped. Returns the paths written.
    """
    out_dir = Path(out_dir)
    written = []
    for kind, reason in available_kinds(recording).items():
        if reason is None:
            fig = figure(kind, recording, depth, meta, **options)
            written.append(save_figure(fig, out_dir / f"{prefix}{kind}.png"))
    return written
