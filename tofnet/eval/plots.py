"""Figures of depth estimates, after the paper's Figures 1, 3, 4, 5 and 6.

Every function returns a ``matplotlib.figure.Figure`` on an Agg canvas, built without
pyplot: no display needed, and the caller's matplotlib backend is left alone.
``save_figure`` writes it as PNG.
Depths are in metres, times in seconds since the run's ``t0``.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from tofnet.errors import DataError
from tofnet.eval.match import match_estimates
from tofnet.eval.metrics import DEFAULT_WINDOW_S, evaluate, window_index
from tofnet.eval.views import (Window, depth_image, depth_range, event_times_us, has_poses, poses_at,
                               resolve_window, sensor_size_of, time_span_us, world_points)

#: Pixels per inch of the PNGs.
DPI = 120
#: Figure size in inches per kind (PNG size = size * DPI).
FIGURE_SIZES = {"depthmap": (12.0, 4.8), "depthmap_single": (7.0, 4.8), "histogram": (8.0, 4.8),
                "error": (10.0, 7.5), "cloud": (9.0, 8.0), "compare": (16.0, 8.5)}
#: Depth colours: turbo reversed (near is red, far is blue), without its two darkest
#: ends so every depth stands out against the dark background of empty pixels.
DEPTH_CMAP = matplotlib.colors.ListedColormap(matplotlib.colormaps["turbo"](np.linspace(0.92, 0.08, 256)),
                                             name="tofnet_depth")
#: Background of pixels without a depth.
EMPTY_COLOUR = "#1a1a1a"
#: Default windows: the paper's Fig. 5 accumulates 70 ms; the others use the whole run.
DEPTHMAP_WINDOW_S = 0.07
#: At most this many points in the 3D view (a fixed random subset beyond that).
CLOUD_MAX_POINTS = 60_000
KINDS = ("depthmap", "histogram", "error", "cloud")


def _span(recording, depth, meta) -> tuple[int, int]:
    return time_span_us(recording.events, depth, int(meta["t0_us"]))


def _window(window, recording, depth, meta, default_s) -> Window:
    if isinstance(window, Window):
        return window
    return resolve_window(window, _span(recording, depth, meta), default_s=default_s)


def _new_figure(kind: str) -> Figure:
    fig = Figure(figsize=FIGURE_SIZES[kind], dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)  # render with Agg, whatever backend pyplot uses
    return fig


def _cmap():
    return DEPTH_CMAP.with_extremes(bad=EMPTY_COLOUR)


def _nice_step(span: float, target_bins: int) -> float:
    """A round bin width (1, 2, 2.5 or 5 times a power of ten) giving about ``target_bins`` bins."""
    raw = max(span, 1e-9) / target_bins
    magnitude = 10.0 ** np.floor(np.log10(raw))
    return float(next(m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw))


def depth_map_figure(recording, depth: np.ndarray, meta: dict, *, window=None, reduce: str = "latest",
                     with_gt: bool = True) -> Figure:
    """Depth accumulated per pixel over a window (paper Fig. 5, 6), beside the ground truth.

    Each pixel shows its ``reduce`` (``"latest"`` or ``"median"``) depth in the window;
    pixels without one stay dark. The ground-truth panel (when the recording has
    ``gt_depth``) accumulates the true depth of the input events of the same window.
    ``window``: a ``Window``, a spec for ``resolve_window`` or None (70 ms, centred).
    """
    win = _window(window, recording, depth, meta, DEPTHMAP_WINDOW_S)
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
    fig = _new_figure(kind)
    axes = fig.subplots(1, len(images), squeeze=False)[0]
    for ax, (name, image) in zip(axes, images):
        shown = ax.imshow(image, cmap=_cmap(), vmin=vmin, vmax=vmax, interpolation="nearest", origin="upper")
        ax.set_facecolor(EMPTY_COLOUR)
        ax.set_title(f"{name} ({np.count_nonzero(np.isfinite(image)):,} px)")
        ax.set_xlabel("x [px]")
        ax.set_ylabel("y [px]")
    fig.colorbar(shown, ax=list(axes), label="depth [m]", shrink=0.9, extend="both")
    fig.suptitle(f"Depth accumulated over {win.label()} ({reduce} per pixel; {len(sel):,} estimates)")
    return fig


def comparison_figure(recording, runs: dict[str, tuple[np.ndarray, dict]], *, window=None,
                      reduce: str = "latest") -> Figure:
    """Several estimators on the same events, side by side: their depth maps over one window
    (and the ground truth's) in one colour range, titled with each one's errors over the whole
    run, and below, the distribution of their signed relative errors.

    ``runs`` maps a label to ``(depth, meta)``; the ground truth needs ``recording.gt_depth``.
    """
    first_depth, first_meta = next(iter(runs.values()))
    win = _window(window, recording, first_depth, first_meta, DEPTHMAP_WINDOW_S)
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
    fig = _new_figure("compare")
    grid = fig.add_gridspec(2 if errors else 1, len(panels), height_ratios=[3, 2] if errors else [1])
    for i, (title, image) in enumerate(panels):
        ax = fig.add_subplot(grid[0, i])
        shown = ax.imshow(image, cmap=_cmap(), vmin=vmin, vmax=vmax, interpolation="nearest", origin="upper")
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
                 "errors over the whole run")
    return fig


def histogram_figure(recording, depth: np.ndarray, meta: dict, *, window=None, with_gt: bool = True,
                     bins: int = 100) -> Figure:
    """Histogram of estimated depths (paper Fig. 4), over the ground truth of the same events.

    The overlay is the true depth of the events the estimates were matched to, so the
    two differ only by the estimation error (and the time discretisation it shows).
    """
    win = _window(window, recording, depth, meta, None)
    inside = win.contains(depth["t"])
    z = depth["z"][inside]
    gt = np.empty(0)
    if with_gt and recording.gt_depth is not None:
        m = match_estimates(depth, recording.events, recording.gt_depth, t0_us=int(meta["t0_us"]),
                            timestep_us=int(meta["timestep_us"]), latency_steps=int(meta["latency_steps"]))
        gt = m.gt[inside & m.valid]
    values = np.concatenate([z, gt])
    top = max(float(np.percentile(values, 99.5)) * 1.05 if len(values) else 1.0, 1e-3)
    width = _nice_step(top, bins)
    edges = np.arange(0.0, top + width, width)
    fig = _new_figure("histogram")
    ax = fig.subplots()
    ax.hist(z, bins=edges, color="tab:blue", alpha=0.75, label=f"estimates ({len(z):,})")
    if len(gt):
        ax.hist(gt, bins=edges, histtype="step", color="black", linewidth=1.4,
                label=f"ground truth of the same events ({len(gt):,})")
    beyond = int(np.count_nonzero(z > edges[-1]))
    ax.set_xlim(edges[0], edges[-1])
    ax.set_xlabel("depth [m]")
    ax.set_ylabel(f"estimates per {width:g} m bin")
    ax.legend(loc="best")
    note = f"; {beyond:,} estimates beyond {edges[-1]:.2f} m not shown" if beyond else ""
    ax.set_title(f"Depth histogram over {win.label()}{note}")
    return fig


def error_figure(recording, depth: np.ndarray, meta: dict, *, window_s: float = DEFAULT_WINDOW_S) -> Figure:
    """Camera motion and the windowed relative error over time (paper Fig. 3).

    Top: camera position in the world (``poses_at``); middle: camera-frame velocity
    (the quantity the network uses; error grows with motion along z); bottom: median
    relative error per ``window_s`` window with its interquartile band.
    """
    ev = evaluate(recording, depth, meta, window_s=window_s)
    t0_us = ev.t0_us
    start_us, end_us = _span(recording, depth, meta)
    traj = recording.trajectory
    rows = (["position"] if has_poses(traj) else []) + (["velocity"] if traj is not None else []) + ["error"]
    fig = _new_figure("error")
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    t_grid = np.linspace(start_us, end_us, 600)
    t_rel = (t_grid - t0_us) * 1e-6
    colours = ("tab:red", "tab:green", "tab:blue")
    for ax, row in zip(axes, rows):
        if row == "position":
            pos, _ = poses_at(traj, t_grid * 1e-6)
            for k, name in enumerate("xyz"):
                ax.plot(t_rel, pos[:, k], color=colours[k], label=name)
            ax.set_ylabel("position (world) [m]")
            ax.set_title("Camera trajectory")
        elif row == "velocity":
            vel = traj.velocity_at(t_grid * 1e-6)
            for k, name in enumerate("xyz"):
                ax.plot(t_rel, vel[:, k], color=colours[k], label=f"$t_{name}$")
            ax.axhline(0.0, color="0.6", linewidth=0.8)
            ax.set_ylabel("velocity (camera) [m/s]")
            ax.set_title("Camera velocity in the camera frame (z = optical axis)")
        else:
            _plot_error(ax, ev, depth["z"])
        ax.grid(True, alpha=0.3)
        if row != "error":
            ax.legend(loc="best", ncols=3, fontsize="small")
    axes[-1].set_xlabel("time since start [s]")
    axes[-1].set_xlim(0.0, (end_us - t0_us) * 1e-6)
    e = ev.errors
    overall = f"; overall mean {e.mean_rel_pct:.1f} %, median {e.median_rel_pct:.1f} %" if e.n else ""
    fig.suptitle(f"Relative depth error over time ({ev.matched:,} matched estimates{overall})")
    return fig


def _plot_error(ax, ev, z: np.ndarray) -> None:
    """Median and interquartile relative error (%) per window of ``ev``, at window centres."""
    m = ev.matches
    valid = m.valid
    rel = np.abs(z[valid] - m.gt[valid]) / m.gt[valid] * 100.0
    win = window_index(m.input_step[valid] * ev.timestep_us, max(1, int(round(ev.window_s * 1e6))))
    n = len(ev.windows)
    keep = (win >= 0) & (win < n)
    order = np.argsort(win[keep], kind="stable")
    w_sorted, r_sorted = win[keep][order], rel[keep][order]
    bounds = np.searchsorted(w_sorted, np.arange(n + 1))
    q = np.full((3, n), np.nan)
    for i in range(n):  # one iteration per window, not per estimate
        if bounds[i + 1] > bounds[i]:
            q[:, i] = np.percentile(r_sorted[bounds[i]:bounds[i + 1]], [25, 50, 75])
    centres = np.array([(w.start_s + w.end_s) / 2 for w in ev.windows])
    ax.fill_between(centres, q[0], q[2], color="tab:purple", alpha=0.25, linewidth=0, label="25\u201375 %")
    ax.plot(centres, q[1], color="tab:purple", marker=".", label="median")
    top = np.nanmax(q[2]) if np.isfinite(q[2]).any() else 1.0
    ax.set_ylim(0.0, top * 1.1)
    ax.set_ylabel("relative error [%]")
    ax.set_title(f"Relative depth error |z \u2212 z_gt| / z_gt per {ev.window_s * 1e3:g} ms window")
    ax.legend(loc="upper right", fontsize="small")


def cloud_figure(recording, depth: np.ndarray, meta: dict, *, window=None,
                 max_points: int = CLOUD_MAX_POINTS) -> Figure:
    """Estimates back-projected to 3D with the camera path (paper Fig. 1).

    Each estimate becomes ``((x-cx)/fx*z, (y-cy)/fy*z, z)`` in the camera frame and is
    moved to the world with the camera pose at the middle of its triggering input step.
    The view is drawn in the frame of the window's first camera pose (right, forward,
    up), so the scene stands upright whatever the world convention.
    """
    win = _window(window, recording, depth, meta, None)
    sel = depth[win.contains(depth["t"])]
    if len(sel) > max_points:  # a fixed subset: the same figure every time
        sel = sel[np.sort(np.random.default_rng(0).choice(len(sel), max_points, replace=False))]
    world = world_points(sel, recording.intrinsics, recording.trajectory, event_times_us(sel, meta))
    traj = recording.trajectory
    path_t = np.linspace(win.start_us, win.end_us, 200) * 1e-6
    path, rotations = poses_at(traj, path_t)
    r0, c0 = rotations[0], path[0]
    pts, cam_path = _to_view(world, r0, c0), _to_view(path, r0, c0)
    lo, hi = _limits(pts, cam_path)
    # 3D axes do not clip: points beyond the limits would be drawn outside the box.
    inside = np.all((pts >= lo) & (pts <= hi), axis=1)
    pts, z = pts[inside], sel["z"][inside]
    vmin, vmax = depth_range(z)
    fig = _new_figure("cloud")
    ax = fig.add_subplot(projection="3d")
    shown = ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=z, cmap=DEPTH_CMAP, vmin=vmin, vmax=vmax,
                       s=1.5, linewidths=0, alpha=0.8, depthshade=False)
    ax.plot(cam_path[:, 0], cam_path[:, 1], cam_path[:, 2], color="black", linewidth=2, label="camera path")
    ax.scatter(*cam_path[0], color="black", marker="o", s=30, label="start")
    # Optical axes at a few poses show where the camera looked.
    for i in np.linspace(0, len(path) - 1, 6).astype(int):
        axis = _to_view(path[i:i + 1] + 0.3 * rotations[i][:, 2], r0, c0)[0]
        ax.plot(*np.column_stack([cam_path[i], axis]), color="0.3", linewidth=1)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.set_xlabel("x, right [m]")
    ax.set_ylabel("z, forward [m]")
    ax.set_zlabel("\u2212y, up [m]", labelpad=8)
    ax.view_init(elev=20, azim=-65)
    ax.legend(loc="upper left", fontsize="small")
    fig.colorbar(shown, ax=ax, label="depth [m]", shrink=0.6, extend="both")
    outside = f", {np.count_nonzero(~inside):,} outside the box" if not inside.all() else ""
    fig.suptitle(f"Depth estimates in 3D over {win.label()}\n({len(pts):,} points{outside}; "
                 f"axes of the first camera pose)")
    return fig


def _to_view(points: np.ndarray, r0: np.ndarray, c0: np.ndarray) -> np.ndarray:
    """World points (m) in the camera frame ``(r0, c0)``, as plot axes (x right, z forward, -y up)."""
    cam = (points - c0) @ r0  # R_wc^T (p - c) for each row
    return np.column_stack([cam[:, 0], cam[:, 2], -cam[:, 1]])


def _limits(points: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A box around the 1-99 percentiles of ``points`` (stray estimates would shrink the
    scene) that holds every row of ``keep`` (the camera path); padded, never flat."""
    both = np.vstack([points, keep])
    lo = np.minimum(np.percentile(both, 1, axis=0), keep.min(axis=0))
    hi = np.maximum(np.percentile(both, 99, axis=0), keep.max(axis=0))
    pad = np.maximum(0.05 * (hi - lo), 0.05)
    return lo - pad, hi + pad


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG at its own size (``DPI``), atomically; returns the path."""
    from tofnet.io.files import atomic_write
    path = Path(path)
    with atomic_write(path) as handle:
        fig.savefig(handle, dpi=DPI, format="png")
    return path


def figure(kind: str, recording, depth: np.ndarray, meta: dict, *, window=None,
           window_s: float = DEFAULT_WINDOW_S, reduce: str = "latest", with_gt: bool = True) -> Figure:
    """The figure of one ``kind`` in ``KINDS``.

    ``window`` selects the time span (``resolve_window``; the error figure always
    covers the whole run), ``window_s`` the error figure's window length in seconds,
    ``reduce`` the depth map's per-pixel rule, ``with_gt`` whether to draw ground truth.
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
            "cloud": None if recording.intrinsics is not None and has_poses(recording.trajectory) else
            "needs intrinsics (calib.txt) and camera poses (groundtruth.txt)"}


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
