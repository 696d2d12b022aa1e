"""EVIMO's metadata dictionary (``meta`` of ``dataset_info.npz`` in EVIMO2 v2, of the sequence's ``.npz`` in
EVIMO and EVIMO2 v1, ``meta.txt`` in the TXT layout): the camera, its Vicon poses and the ground-truth frames' times.

The dictionary is pickled; ``tofnet.io.npz_object`` reads it without running anything from the file.
Every value is checked here: a wrong type or a number that is not finite is one line naming its key
(``dataset_info.npz[meta].meta.fx: expected a finite number, got 'x'``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.recording import Intrinsics


def read_meta(path: Path) -> dict:
    """The metadata dictionary stored as ``meta`` in the ``.npz`` file ``path``."""
    from tofnet.io.npz_object import read_npz_object
    return mapping(read_npz_object(path, "meta"), f"{path}[meta]")


#: The largest ``meta.txt`` read (bytes): EVIMO2's hold every Vicon sample of every object, a few MB.
MAX_META_TEXT_BYTES = 256 * 2**20


def read_meta_text(path: Path) -> dict:
    """The metadata dictionary of EVIMO's TXT layout (``meta.txt``, a Python literal), read as a literal only."""
    import ast

    from tofnet.io.files import read_text

    text = read_text(path, "EVIMO metadata (meta.txt)", limit=MAX_META_TEXT_BYTES)
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError) as err:
        raise DataError(located(path, None, f"not a Python literal (EVIMO's metadata dictionary): "
                                            f"{type(err).__name__}")) from None
    return mapping(value, str(path))


def camera(meta: dict, where: str) -> tuple[Intrinsics, tuple[int, int]]:
    """Intrinsics and sensor size (px) from ``meta['meta']`` (``fx fy cx cy``, ``dist_model`` with ``k1..k4 p1 p2``,
    ``res_x res_y``)."""
    from tofnet.io.calibration import intrinsics_from

    where = f"{where}.meta"
    cam = mapping(meta.get("meta"), where)
    model = str(cam.get("dist_model", "radtan"))
    names = ("k1", "k2", "k3", "k4") if model in ("equidistant", "fisheye", "kb4") else ("k1", "k2", "p1", "p2", "k3")
    values = [number(cam.get(key), f"{where}.{key}") for key in ("fx", "fy", "cx", "cy")]
    coefficients = [number(cam.get(key, 0.0), f"{where}.{key}") for key in names]
    try:
        intrinsics = intrinsics_from(values, coefficients, model)
    except ValueError as err:
        raise DataError(located(where, None, str(err))) from None
    width, height = (int(number(cam.get(key), f"{where}.{key}")) for key in ("res_x", "res_y"))
    return intrinsics, (width, height)


def poses(meta: dict, where: str, notes: list[str]):
    """The camera's poses (``tofnet.io.groundtruth.Trajectory``, camera to EVIMO's world: the recording's first
    camera frame) from ``meta['full_trajectory']``; ``None`` (noted) without it. Samples without a camera pose
    (EVIMO writes one in every sample; a file that does not) are left out and counted in ``notes``."""
    from tofnet.io.groundtruth import Trajectory

    samples, where = meta.get("full_trajectory"), f"{where}.full_trajectory"
    if samples is None:
        notes.append("no full_trajectory in the metadata: no poses")
        return None
    rows, lost = [], 0
    for k, sample in enumerate(sequence(samples, where)):
        cam = mapping(sample, f"{where}[{k}]").get("cam")
        if cam is None:
            lost += 1
            continue
        pos = mapping(mapping(cam, f"{where}[{k}].cam").get("pos"), f"{where}[{k}].cam.pos")
        t, q = (mapping(pos.get(key), f"{where}[{k}].cam.pos.{key}") for key in ("t", "q"))
        rows.append([number(sample.get("ts", cam.get("ts")), f"{where}[{k}].ts")]
                    + [number(t.get(a), f"{where}[{k}].cam.pos.t.{a}") for a in "xyz"]
                    + [number(q.get(a), f"{where}[{k}].cam.pos.q.{a}") for a in "xyzw"])
    if lost:
        notes.append(f"{lost:,} of {lost + len(rows):,} pose samples without the camera's pose: the poses are "
                     "interpolated across them")
    table = np.asarray(rows, dtype=np.float64).reshape(-1, 8)
    return Trajectory(table[:, 0], table[:, 1:4], table[:, 4:8], where)


def ground_truth_frames(meta: dict, where: str) -> list[tuple[int, int, float]]:
    """``(position in meta['frames'], id, time s)`` of the frames that have ground truth (``gt_frame``; every frame
    when none says), in their order (an ``id`` absent: the position)."""
    frames, where = meta.get("frames"), f"{where}.frames"
    frames = [mapping(frame, f"{where}[{k}]") for k, frame in enumerate(sequence(frames or [], where))]
    marked = any("gt_frame" in frame for frame in frames)
    return [(k, int(number(frame.get("id", k), f"{where}[{k}].id")), number(frame.get("ts"), f"{where}[{k}].ts"))
            for k, frame in enumerate(frames) if "gt_frame" in frame or not marked]


def mapping(value, where: str) -> dict:
    """``value`` when it is a dictionary, else a one-line ``DataError`` naming ``where``."""
    if not isinstance(value, dict):
        raise DataError(located(where, None, f"expected a dictionary, got {type(value).__name__}"))
    return value


def sequence(value, where: str) -> list:
    """``value`` as a list when it is one (or a tuple), else a one-line ``DataError`` naming ``where``."""
    if not isinstance(value, (list, tuple)):
        raise DataError(located(where, None, f"expected a list, got {type(value).__name__}"))
    return list(value)


def number(value, where: str) -> float:
    """``value`` as a finite float (not a bool), else a one-line ``DataError`` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(value)):
        raise DataError(located(where, None, f"expected a finite number, got {str(value)[:40]!r}"))
    return float(value)
