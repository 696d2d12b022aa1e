"""EVIMO's metadata dictionary (``meta`` of ``dataset_info.npz`` in EVIMO2 v2, of the sequence's ``.npz`` in
EVIMO and EVIMO2 v1, ``meta.txt`` in the TXT layout): the camera, its Vicon poses and the ground-truth frames' times.

The dictionary is pickled; ``tofnet.io.npz_object`` reads it without running anything from the file.
Every value is checked here: a wrong type or a number that is not finite is one line naming its key
(``dataset_info.npz[meta].meta.fx: expected a finite number, got 'x'``).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tofnet.errors import DataError, located
from tofnet.io.recording import Intrinsics

if TYPE_CHECKING:
    from tofnet.io.groundtruth import Trajectory


def read_meta(path: Path) -> dict:
    """The metadata dictionary stored as ``meta`` in the ``.npz`` file ``path``."""
    from tofnet.io.npz_object import read_npz_object
    return mapping(read_npz_object(path, "meta"), f"{path}[meta]")


#: The largest ``meta.txt`` read (bytes): EVIMO2's hold every Vicon sample of every object (~25 MB a minute).
MAX_META_TEXT_BYTES = 256 * 2**20
#: The deepest nesting of a ``meta.txt`` literal (EVIMO's is 5 deep).
MAX_NESTING = 64
_TOKEN = re.compile(r"""\s*(?:(?P<str>'(?:[^'\\\n]|\\.)*'|"(?:[^"\\\n]|\\.)*")"""
                    r"|(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
                    r"|(?P<word>True|False|None)|(?P<punct>[{}\[\](),:]))")
_OPEN = {"{": "}", "[": "]", "(": ")"}


def read_meta_text(path: Path) -> dict:
    """The metadata dictionary of EVIMO's TXT layout (``meta.txt``, a Python literal of dicts, lists, strings and
    numbers), parsed token by token (``ast.literal_eval`` takes ~180 bytes of memory per byte of text)."""
    from tofnet.io.files import read_text

    text = read_text(path, "EVIMO metadata (meta.txt)", limit=MAX_META_TEXT_BYTES)
    return mapping(parse_literal(text, str(path)), str(path))


def parse_literal(text: str, where: str) -> object:
    """The value of a Python literal of dicts, lists, tuples, strings, numbers, True, False and None; a one-line
    ``DataError`` naming ``where`` and the character where it stops being one."""
    import ast

    stack: list[list] = []  # [container, key or _NO_KEY, what comes next: "value", "colon" or "separator"]
    root, pos, end = _NO_KEY, 0, len(text)

    def fail(why: str) -> DataError:
        return DataError(located(where, None, f"not a Python literal (EVIMO's metadata dictionary) at character "
                                              f"{pos:,}: {why}"))

    def add(value) -> None:
        nonlocal root
        if not stack:
            if root is not _NO_KEY:
                raise fail("a second value after the first")
            root = value
            return
        top = stack[-1]
        if top[2] != "value":
            raise fail(f"expected {'a colon' if top[2] == 'colon' else 'a comma or a closing bracket'}")
        if isinstance(top[0], dict) and top[1] is _NO_KEY:
            if isinstance(value, (dict, list)):  # a tuple too, until it closes: no key of EVIMO's is one
                raise fail("a dictionary key must be a string, a number, True, False or None")
            top[1], top[2] = value, "colon"
        elif isinstance(top[0], dict):
            top[0][top[1]], top[1], top[2] = value, _NO_KEY, "separator"
        else:
            top[0].append(value)
            top[2] = "separator"

    while True:
        match = _TOKEN.match(text, pos)
        if match is None:
            if text[pos:].strip():
                raise fail("unexpected text")
            break
        pos = match.end()
        kind, token = match.lastgroup, match.group(match.lastgroup)
        try:
            if kind == "str":
                add(ast.literal_eval(token) if "\\" in token else token[1:-1])
            elif kind == "num":
                add(float(token) if any(c in token for c in ".eE") else int(token))
            elif kind == "word":
                add({"True": True, "False": False, "None": None}[token])
            elif token in _OPEN:
                if len(stack) >= MAX_NESTING:
                    raise fail(f"nested more than {MAX_NESTING} deep")
                container = {} if token == "{" else []
                add(container)
                stack.append([container, _NO_KEY, "value", _OPEN[token]])
            elif token == ":" and stack and stack[-1][2] == "colon":
                stack[-1][2] = "value"
            elif token == "," and stack and stack[-1][2] == "separator":
                stack[-1][2] = "value"
            elif stack and token == stack[-1][3] and (stack[-1][2] == "separator" or stack[-1][1] is _NO_KEY):
                container = stack.pop()[0]
                if token == ")" and stack:  # a tuple: the list its parent holds becomes one
                    parent = stack[-1][0]
                    if isinstance(parent, dict):
                        key = next(k for k in reversed(parent) if parent[k] is container)
                        parent[key] = tuple(container)
                    else:
                        parent[-1] = tuple(container)
            else:
                raise fail(f"unexpected {token!r}")
        except (ValueError, SyntaxError, TypeError, MemoryError) as err:  # a number, string or key Python does not take
            raise fail(f"{type(err).__name__}") from None
    if stack or root is _NO_KEY:
        raise fail("the text ends inside a bracket" if stack else "no value")
    return tuple(root) if isinstance(root, list) and text.lstrip().startswith("(") else root


_NO_KEY = object()


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
    width, height = (whole(cam.get(key), f"{where}.{key}") for key in ("res_x", "res_y"))
    return intrinsics, (width, height)


def poses(meta: dict, where: str, notes: list[str]) -> Trajectory | None:
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


def mapping(value: object, where: str) -> dict:
    """``value`` when it is a dictionary, else a one-line ``DataError`` naming ``where``."""
    if not isinstance(value, dict):
        raise DataError(located(where, None, f"expected a dictionary, got {type(value).__name__}"))
    return value


def sequence(value: object, where: str) -> list:
    """``value`` as a list when it is one (or a tuple), else a one-line ``DataError`` naming ``where``."""
    if not isinstance(value, (list, tuple)):
        raise DataError(located(where, None, f"expected a list, got {type(value).__name__}"))
    return list(value)


def number(value: object, where: str) -> float:
    """``value`` as a finite float (not a bool), else a one-line ``DataError`` naming ``where``."""
    try:
        finite = (not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
                  and math.isfinite(float(value)))
    except OverflowError:  # an int beyond any float
        finite = False
    if not finite:
        plain = isinstance(value, (float, str, bool, type(None))) or (isinstance(value, int) and value.bit_length() < 64)
        shown = repr(value[:40] if isinstance(value, str) else value) if plain else type(value).__name__
        raise DataError(located(where, None, f"expected a finite number, got {shown}"))
    return float(value)


def whole(value: object, where: str) -> int:
    """``value`` as a whole number (pixels), else a one-line ``DataError`` naming ``where``."""
    number_ = number(value, where)
    if number_ != math.floor(number_):
        raise DataError(located(where, None, f"expected a whole number, got {number_:g}"))
    return int(number_)
