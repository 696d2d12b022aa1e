"""The estimates in 3D (after the paper's Fig. 1): the cloud binned along rays and coloured by
depth and, beside it, every estimate seen from above as a density map, both with the camera's path.

Distances are in metres, in the axes of the window's first camera pose (x right, z forward,
-y up), so the scene stands upright whatever the world convention.
"""

from __future__ import annotations

import numpy as np
from matplotlib.colors import LogNorm, Normalize
from matplotlib.figure import Figure

from tofnet.eval.bins import depth_lattice, ray_medians
from tofnet.eval.plots_base import DEPTH_CMAP, EMPTY_COLOUR, figure_window, new_figure
from tofnet.eval.views import depth_range, event_times_us, poses_at, sensor_size_of, world_points

#: Default viewpoint of the 3D view (elevation, azimuth; degrees): a little above and
#: behind the camera's left shoulder, looking into the scene as the camera did.
CLOUD_VIEW = (15.0, -75.0)
#: The 3D view's ray cells are this many pixels (of the first pose) wide, and a cell is drawn
#: when at least ``CELL_LEAST`` estimates fall in it and they agree: the middle half of
#: their depths spans at most ``CELL_AGREE`` of their median.
CELL_PX, CELL_LEAST, CELL_AGREE = 3, 3, 0.3
#: Cells along the longest side of the top view.
TOP_CELLS = 160


def cloud_figure(recording, depth: np.ndarray, meta: dict, *, window=None,
                 view: tuple[float, float] = CLOUD_VIEW) -> Figure:
    """Estimates back-projected to 3D with the camera path (paper Fig. 1).

    Each estimate becomes ``((x-cx)/fx*z, (y-cy)/fy*z, z)`` in the camera frame and is
    moved to the world with the camera pose at the middle of its triggering input step.
    Left, seen from ``view`` (elevation, azimuth in degrees): the estimates grouped by
    direction from the first pose into cells ``CELL_PX`` pixels wide, one point per cell
    at their median depth (``ray_medians``) where they agree (``CELL_AGREE``), so estimates
    that a timing error scattered along a ray gather on the surface; right, every estimate
    seen from above, counted per cell.
    """
    win = figure_window(window, recording, depth, meta, None)
    sel = depth[win.contains(depth["t"])]
    world = world_points(sel, recording.intrinsics, recording.trajectory, event_times_us(sel, meta))
    path, rotations = poses_at(recording.trajectory, np.linspace(win.start_us, win.end_us, 200) * 1e-6)
    r0, c0 = rotations[0], path[0]
    cam = (world - c0) @ r0  # in the first pose's camera frame: R_wc^T (p - c)
    cells, _, spread = ray_medians(cam, CELL_PX / recording.intrinsics.fx, CELL_LEAST)
    cells, disagree = cells[spread <= CELL_AGREE], int(np.count_nonzero(spread > CELL_AGREE))
    pts, cam_path = _to_view(cells), _to_view((path - c0) @ r0)
    lo, hi = _limits(pts, cam_path)
    # 3D axes do not clip: points beyond the limits would be drawn outside the box.
    inside = np.all((pts >= lo) & (pts <= hi), axis=1)
    norm = Normalize(*depth_range(cells[inside, 2]))

    fig = new_figure("cloud")
    grid = fig.add_gridspec(1, 2, width_ratios=[3, 2])
    ax = fig.add_subplot(grid[0], projection="3d")
    shown = ax.scatter(pts[inside, 0], pts[inside, 1], pts[inside, 2], c=cells[inside, 2], cmap=DEPTH_CMAP,
                       norm=norm, s=5, linewidths=0, depthshade=False)
    ax.plot(cam_path[:, 0], cam_path[:, 1], cam_path[:, 2], color="black", linewidth=2.5, label="camera path")
    ax.scatter(*cam_path[0], color="black", marker="o", s=30, label="start")
    # Optical axes at a few poses show where the camera looked.
    for i in np.linspace(0, len(path) - 1, 6).astype(int):
        axis = _to_view((path[i:i + 1] + 0.3 * rotations[i][:, 2] - c0) @ r0)[0]
        ax.plot(*np.column_stack([cam_path[i], axis]), color="0.3", linewidth=1)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo, zoom=1.2)
    ax.set_xlabel("x, right [m]")
    ax.set_ylabel("z, forward [m]")
    ax.set_zlabel("\u2212y, up [m]", labelpad=8)
    ax.view_init(elev=view[0], azim=view[1])
    ax.legend(loc="upper left", fontsize="small")
    ax.set_title(f"median depth per {CELL_PX}\u00d7{CELL_PX} px ray of the first pose where \u2265 {CELL_LEAST} "
                 f"estimates agree\n(interquartile range \u2264 {CELL_AGREE:.0%} of the median): "
                 f"{np.count_nonzero(inside):,} rays; {disagree:,} others disagree, not drawn", fontsize="medium")
    fig.colorbar(shown, ax=ax, label="depth [m]", shrink=0.6, extend="both", pad=0.08)
    beyond = _top_view(fig.add_subplot(grid[1]), _to_view(cam), cam_path, lo, hi, recording, sel)
    outside = f", {beyond:,} outside the box" if beyond else ""
    fig.suptitle(f"Depth estimates in 3D over {win.label()}: {len(sel):,} estimates{outside}; "
                 "axes of the first camera pose")
    return fig


def _top_view(ax, pts: np.ndarray, cam_path: np.ndarray, lo: np.ndarray, hi: np.ndarray, recording,
              depth: np.ndarray) -> int:
    """Every estimate seen from above (x right, z forward), counted per square cell on a log
    scale, with the camera path and the first pose's field of view; returns how many fall
    outside the box. A cell is at least one counter step of the depths (``depth_lattice``) deep,
    so whole-step depths leave no empty stripes between them."""
    step = depth_lattice(depth["z"]) or 0.0
    cell = max(float(max(hi[0] - lo[0], hi[1] - lo[1])) / TOP_CELLS, step)
    xs = np.arange(lo[0], hi[0] + cell, cell)
    zs = np.arange(lo[1], hi[1] + cell, cell)
    counts, _, _ = np.histogram2d(pts[:, 0], pts[:, 1], bins=[xs, zs])
    beyond = len(pts) - int(counts.sum())
    counts = np.where(counts > 0, counts, np.nan).T
    ax.set_facecolor(EMPTY_COLOUR)
    top = max(2.0, float(np.nanmax(counts))) if np.isfinite(counts).any() else 2.0
    image = ax.pcolormesh(xs, zs, counts, cmap="magma", norm=LogNorm(vmin=1, vmax=top))
    # The field of view of the first pose: the rays through the sensor's left and right edges.
    k, width = recording.intrinsics, sensor_size_of(recording, depth)[0]
    reach = hi[1] - cam_path[0, 1]
    for u in (-0.5, width - 0.5):
        ax.plot([cam_path[0, 0], cam_path[0, 0] + (u - k.cx) / k.fx * reach], [cam_path[0, 1], hi[1]],
                color="0.75", linewidth=0.8, linestyle="--")
    ax.plot(cam_path[:, 0], cam_path[:, 1], color="white", linewidth=2.5, label="camera path")
    ax.scatter(cam_path[0, 0], cam_path[0, 1], color="white", s=25, zorder=3)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x, right [m]")
    ax.set_ylabel("z, forward [m]")
    ax.set_title("every estimate, seen from above (dashed: the first field of view)", fontsize="medium")
    ax.figure.colorbar(image, ax=ax, label=f"estimates per {cell * 100:.2g} cm cell", shrink=0.8)
    return beyond


def _to_view(cam: np.ndarray) -> np.ndarray:
    """Camera-frame points (m) as plot axes: x right, z forward, -y up."""
    return np.column_stack([cam[:, 0], cam[:, 2], -cam[:, 1]])


def _limits(points: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A box around the 1-99 percentiles of ``points`` (stray estimates would shrink the
    scene) that holds every row of ``keep`` (the camera path); padded, never flat."""
    both = np.vstack([points, keep])
    lo = np.minimum(np.percentile(both, 1, axis=0), keep.min(axis=0))
    hi = np.maximum(np.percentile(both, 99, axis=0), keep.max(axis=0))
    pad = np.maximum(0.05 * (hi - lo), 0.05)
    return lo - pad, hi + pad
