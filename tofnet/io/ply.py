"""Depth estimates as a point cloud: ``.ply`` (binary little-endian or ASCII) for Open3D, PCL, ROS.

Each estimate ``(t, x, y, z)`` is back-projected through the pinhole camera:
``X = x_n Z``, ``Y = y_n Z`` with ``(x_n, y_n)`` the normalised coordinates of the pixel,
undistorted first when the intrinsics have distortion and the pixels are raw sensor
pixels. Camera frame: OpenCV (x right, y down, z forward), metres. World frame: the
frame of the recording's poses, ``p_w = R_wc(t) p_c + c(t)`` at the estimate's time.

Vertices carry ``float x, y, z`` (what PCL's ``PointXYZ`` and Open3D read) and, when
asked, ``uchar red, green, blue`` colouring the depth (matplotlib's turbo map).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tofnet.errors import DataError

FRAMES = ("camera", "world")


def depth_points(depth: np.ndarray, intrinsics, trajectory=None, *, frame: str = "camera",
                 raw_pixels: bool = True, chunk: int = 1_000_000) -> np.ndarray:
    """``(n, 3)`` float64 points (m) of ``DEPTH_DTYPE`` estimates in the camera or world frame.

    ``raw_pixels``: the estimates' pixels are raw sensor pixels (tofnet's network runs on
    them), so the lens distortion is undone before back-projecting; pass ``False`` for
    pixels already undistorted. Points whose pixel has no undistortion are NaN.
    """
    if frame not in FRAMES:
        raise DataError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    if intrinsics is None:
        raise DataError("a point cloud needs the camera intrinsics (calib.txt or the recording's calibration)")
    if frame == "world" and (trajectory is None or not hasattr(trajectory, "pose_at")):
        raise DataError("the world frame needs the recording's poses (groundtruth.txt or the file's pose stream)")
    x_n = (depth["x"].astype(np.float64) - intrinsics.cx) / intrinsics.fx
    y_n = (depth["y"].astype(np.float64) - intrinsics.cy) / intrinsics.fy
    if raw_pixels and intrinsics.distortion:
        from tofnet.kernels.undistort import undistort
        x_n, y_n = undistort(x_n, y_n, intrinsics.distortion_model, intrinsics.distortion)
    z = depth["z"].astype(np.float64)
    points = np.column_stack([x_n * z, y_n * z, z])
    if frame == "world":
        for start in range(0, len(points), chunk):
            part = slice(start, start + chunk)
            positions, rotations = trajectory.pose_at(depth["t"][part] * 1e-6)
            points[part] = np.einsum("nij,nj->ni", rotations, points[part]) + positions
    return points


def depth_colors(z: np.ndarray) -> np.ndarray:
    """``(n, 3)`` uint8 RGB colouring depth from its 2nd to 98th percentile (turbo)."""
    from matplotlib import colormaps

    if len(z) == 0:
        return np.zeros((0, 3), dtype=np.uint8)
    low, high = np.nanpercentile(z, [2, 98])
    scaled = np.clip((z - low) / (high - low if high > low else 1.0), 0, 1)
    return (colormaps["turbo"](scaled)[:, :3] * 255 + 0.5).astype(np.uint8)


def write_ply(path: str | Path, points: np.ndarray, *, colors: np.ndarray | None = None, binary: bool = True,
              comment: str = "") -> int:
    """Write finite ``points`` (n, 3) as PLY vertices; returns how many were written (NaN rows skipped).

    The file appears under ``path`` only once complete.
    """
    path = Path(path)
    keep = np.all(np.isfinite(points), axis=1)
    vertices = np.empty(int(keep.sum()), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")] +
                        ([("red", "u1"), ("green", "u1"), ("blue", "u1")] if colors is not None else []))
    for k, name in enumerate("xyz"):
        vertices[name] = points[keep, k]
    if colors is not None:
        for k, name in enumerate(("red", "green", "blue")):
            vertices[name] = colors[keep, k]
    header = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0"]
    header += [f"comment {line}" for line in comment.splitlines() if line]
    header += [f"element vertex {len(vertices)}", "property float x", "property float y", "property float z"]
    if colors is not None:
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    header.append("end_header")
    from tofnet.io.files import atomic_write

    with atomic_write(path) as handle:
        handle.write(("\n".join(header) + "\n").encode("ascii"))
        if binary:
            handle.write(vertices.tobytes())
        else:
            table = np.column_stack([vertices[name].astype(np.float64) for name in vertices.dtype.names])
            fmt = "%.9g %.9g %.9g" + (" %d %d %d" if colors is not None else "")
            np.savetxt(handle, table.reshape(-1, len(vertices.dtype.names)), fmt=fmt)
    return len(vertices)
