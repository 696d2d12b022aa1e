"""Camera intrinsics in the ECD ``calib.txt`` format."""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import DataError, located
from tofnet.io.files import write_text_atomic
from tofnet.io.groundtruth import finite_number, read_text
from tofnet.io.recording import Intrinsics

_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def read_calibration(path: str | Path) -> Intrinsics:
    """Read ECD ``calib.txt``: one line ``fx fy cx cy [k1 k2 p1 p2 k3]`` (pixels; distortion unitless).

    Blank lines and ``#`` comments are allowed around the line. Four numbers give no
    distortion; nine give ``distortion = (k1, k2, p1, p2, k3)``.
    """
    path = Path(path)
    data = [(n, line.strip()) for n, line in enumerate(read_text(path).splitlines(), start=1)
            if line.strip() and not line.strip().startswith("#")]
    if not data:
        raise DataError(located(path, None, "empty calibration; expected one line 'fx fy cx cy k1 k2 p1 p2 k3'"))
    if len(data) > 1:
        raise DataError(located(path, data[1][0], "expected one line 'fx fy cx cy k1 k2 p1 p2 k3', found another"))
    number, line = data[0]
    fields = line.split()
    if len(fields) not in (4, 9):
        raise DataError(located(path, number, f"expected 4 numbers 'fx fy cx cy' or 9 'fx fy cx cy k1 k2 p1 p2 k3', "
                                              f"found {len(fields)}"))
    values = [finite_number(path, number, f"'{name}'", field) for name, field in zip(_NAMES, fields)]
    for name, value in zip(("fx", "fy"), values[:2]):
        if value <= 0:
            raise DataError(located(path, number, f"'{name}': focal length must be positive (pixels), got {value:g}"))
    return Intrinsics(*values[:4], distortion=tuple(values[4:]))


def write_calibration(path: str | Path, intrinsics: Intrinsics) -> None:
    """Write ``fx fy cx cy`` and, when present, the five distortion coefficients on one line."""
    path = Path(path)
    values = (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy, *intrinsics.distortion)
    if len(values) not in (4, 9):
        raise DataError(located(path, None, f"distortion must have 5 coefficients (k1 k2 p1 p2 k3) or none, "
                                            f"got {len(intrinsics.distortion)}"))
    # repr() is the shortest text that reads back to the same float.
    write_text_atomic(path, " ".join(repr(float(v)) for v in values) + "\n")
