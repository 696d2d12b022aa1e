"""Camera intrinsics: ECD ``calib.txt``, ``--intrinsics`` text, and the calibration files datasets ship."""

from __future__ import annotations

import math
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from tofnet.errors import DataError, TofnetError, field_hidden, located, quote, quote_field
from tofnet.io.files import write_text_atomic
from tofnet.io.groundtruth import finite_number, read_text
from tofnet.io.recording import Intrinsics, focal_problem

_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
#: The note of a recording without a camera (an ECD folder or file without ``calib.txt``).
NO_CALIBRATION = "no calib.txt: intrinsics unknown"


def read_calibration(path: str | Path) -> Intrinsics:
    """Read ECD ``calib.txt``: one line ``fx fy cx cy [k1 k2 p1 p2 k3]`` (pixels; distortion unitless).

    Blank lines and ``#`` comments are allowed around the line. Four numbers give no
    distortion; nine give ``distortion = (k1, k2, p1, p2, k3)``; eight, ``k3 = 0``.
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
    if len(fields) not in (4, 8, 9):
        raise DataError(located(path, number, f"expected 4 numbers 'fx fy cx cy' or 9 'fx fy cx cy k1 k2 p1 p2 k3' "
                                              f"(8: k3 = 0), found {len(fields)}"))
    values = [finite_number(path, number, f"'{name}'", field) for name, field in zip(_NAMES, fields)]
    values += [0.0] if len(values) == 8 else []
    if focal_problem(*values[:2]):
        raise DataError(located(path, number, focal_problem(*values[:2])))
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


def parse_intrinsics(text: str, what: str = "--intrinsics") -> Intrinsics:
    """``fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]`` (pixels; radtan coefficients, k3 = 0 when absent)."""
    fields = [f.strip() for f in str(text).replace(" ", ",").split(",") if f.strip()]
    if len(fields) not in (4, 8, 9):
        raise TofnetError(f"{what}: expected fx,fy,cx,cy or fx,fy,cx,cy,k1,k2,p1,p2[,k3] (pixels), "
                          f"got {len(fields)} numbers in {quote(text)}")
    values = []
    for name, field in zip(_NAMES, fields):
        try:
            value = float(field)
        except ValueError:
            value = float("nan")
        if not math.isfinite(value):
            raise TofnetError(f"{what}: '{name}' is not a finite number: {quote(field)}")
        values.append(value)
    if focal_problem(values[0], values[1]):
        raise TofnetError(f"{what}: {focal_problem(values[0], values[1])}")
    distortion = tuple(values[4:]) + ((0.0,) if len(values) == 8 else ())
    return Intrinsics(*values[:4], distortion=distortion if any(distortion) else ())


def read_camera_file(path: str | Path, camera: str | None = None,
                     sensor_size: tuple[int, int] | None = None) -> tuple[Intrinsics, tuple[int, int] | None, str]:
    """Intrinsics (and the image size, when given) from a calibration file, by its content:

    - ECD ``calib.txt``: ``fx fy cx cy [k1 k2 p1 p2 k3]``;
    - Kalibr camchain YAML (MVSEC's ``camchain-imucam``): ``camN: {intrinsics: [fu, fv, pu, pv],
      distortion_model, distortion_coeffs, resolution}``;
    - DSEC ``cam_to_cam.yaml``: ``intrinsics: {camN: {camera_matrix, distortion_model, distortion_coeffs,
      resolution}}`` (events: cam0 left, cam3 right);
    - a TUM-VIE / Basalt calibration JSON: ``value0: {intrinsics: [{camera_type, intrinsics: {fx, ..., k4}}],
      resolution: [[w, h], ...]}``;
    - a ROS ``camera_info`` YAML: ``image_width``, ``image_height``, ``camera_matrix.data`` (3x3),
      ``distortion_model``, ``distortion_coefficients.data``.

    With several cameras, ``camera`` picks one (a name such as ``cam3``, or an index); without it,
    the first whose resolution equals ``sensor_size``, else the first. Returns ``(intrinsics, (width,
    height) or None, what was used)``; errors are one line naming the file and the key.
    """
    from tofnet.io.files import read_text as read_limited

    path = Path(path)
    text = read_limited(path, "calibration file", limit=1 << 20)
    if text.lstrip().startswith("{"):
        from tofnet.io.jsontext import parse_json
        data = parse_json(text, path)
    else:
        if _looks_like_calib_txt(text):
            return read_calibration(path), None, "calib.txt"
        from tofnet.io.safe_yaml import read_yaml_file
        data = read_yaml_file(path, "calibration")
    try:  # its fields are quoted as the text readers' are: cut to 40 characters, never from a file linked out
        return _camera_from(data, camera, sensor_size, partial(quote_field, path), field_hidden(path))
    except IntrinsicsError as err:
        raise DataError(located(path, None, str(err))) from None
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError) as err:
        raise DataError(located(path, None, f"{_reason(err)}; expected a calib.txt, a Kalibr/DSEC camera YAML, "
                                            "a TUM-VIE calibration JSON or a ROS camera_info YAML")) from None


def _reason(err: BaseException) -> str:
    """The first line of an error of the layout. The messages raised here quote the file's fields through
    ``quote_field`` (numbers too: ``_numbers``, ``_size``) and Python's own that remain (a key tofnet asked
    for, a wrong type) hold none, so the line is not cut at a length that would drop what was expected
    after two long paths; the cap only keeps it readable."""
    if isinstance(err, KeyError):
        return f"no key {err.args[0]!r}" if err.args else "a key is missing"
    return str(err).split("\n")[0][:800] or type(err).__name__


def _numbers(values, what: str, show: Callable[[object], str] = quote) -> list[float]:
    """``values`` (any nesting) as floats: one that is not a number is named through ``show``, not by
    float()'s own message, which quotes all of it."""
    out = []
    for value in np.ravel(np.asarray(values, dtype=object)):
        try:
            out.append(float(value))
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"{what}: expected a number, got {show(value)}") from None
    return out


def _looks_like_calib_txt(text: str) -> bool:
    lines = [line.strip() for line in text.splitlines() if line.strip() and not line.strip().startswith("#")]
    return len(lines) == 1 and all(is_number(f) for f in lines[0].split())



#: Distortion model names as datasets write them -> tofnet's (``Intrinsics.distortion_model``).
MODEL_NAMES = {"radtan": "radtan", "plumb_bob": "radtan", "radial-tangential": "radtan", "pinhole": "radtan",
               "none": "radtan",
               "equidistant": "equidistant", "fisheye": "equidistant", "kb4": "equidistant"}


def intrinsics_from(matrix, coefficients, model: str, show: Callable[[object], str] = quote) -> Intrinsics:
    """``Intrinsics`` from ``[fx, fy, cx, cy]`` and distortion coefficients of a named model.

    radtan: ``k1 k2 p1 p2 [k3]`` (k3 = 0 when absent); equidistant: ``k1 k2 k3 k4``. ``show`` quotes a
    field of the file in an error (``quote_field``).
    """
    model_name = MODEL_NAMES.get(str(model).lower().strip())
    if model_name is None:
        raise ValueError(f"unknown distortion model {show(str(model))}; expected one of "
                         f"{', '.join(sorted(MODEL_NAMES))}")
    coefficients = tuple(_numbers(coefficients, "distortion coefficients", show))
    if str(model).lower().strip() == "none":  # Kalibr's and others' word for a lens without distortion
        if any(coefficients):
            raise ValueError(f"distortion model 'none' with coefficients {', '.join(f'{c:g}' for c in coefficients)}")
        coefficients = ()
    if model_name == "radtan" and len(coefficients) == 4:
        coefficients = coefficients + (0.0,)
    expected = 5 if model_name == "radtan" else 4
    if coefficients and len(coefficients) != expected:
        raise ValueError(f"{model_name} distortion needs {expected} coefficients, got {len(coefficients)}")
    if not any(coefficients):
        coefficients = ()
    matrix = _numbers(matrix, "fx fy cx cy", show)
    if len(matrix) != 4:
        raise ValueError(f"expected 4 numbers fx fy cx cy, got {len(matrix)}")
    fx, fy, cx, cy = (float(v) for v in matrix)
    check_intrinsics(fx, fy, cx, cy, coefficients)
    return Intrinsics(fx, fy, cx, cy, distortion=coefficients,
                      distortion_model=model_name if coefficients else "radtan")


class IntrinsicsError(ValueError):
    """Intrinsics no camera has, in a file whose layout was understood."""


def check_intrinsics(fx: float, fy: float, cx: float, cy: float, coefficients: tuple[float, ...] = ()) -> None:
    """Refuse what no camera has (``IntrinsicsError``, one line): focal lengths below 1 px (``focal_problem``), a
    principal point or a distortion coefficient not finite. All zeros is ROS's uncalibrated camera."""
    if fx == fy == cx == cy == 0.0:
        raise IntrinsicsError("the camera matrix is all zeros (an uncalibrated camera); give the calibration "
                              "with --calib FILE or --intrinsics fx,fy,cx,cy")
    for name, value in (("fx", fx), ("fy", fy), ("cx", cx), ("cy", cy)):
        if not math.isfinite(value):
            raise IntrinsicsError(f"{name} is {value}; expected a finite number of pixels")
    if focal_problem(fx, fy):
        raise IntrinsicsError(focal_problem(fx, fy))
    if not all(math.isfinite(c) for c in coefficients):
        raise IntrinsicsError(f"distortion coefficients must be finite, got {', '.join(f'{c:g}' for c in coefficients)}")


def is_number(field: str) -> bool:
    """Whether ``field`` reads as a float."""
    try:
        float(field)
        return True
    except ValueError:
        return False


def _camera_from(data, camera, sensor_size, show: Callable[[object], str] = quote, hidden: str | None = None):
    """The camera of a parsed calibration file; ``show`` quotes its fields, ``hidden`` (``field_hidden``)
    stands for its camera names when they may not be shown."""
    if not isinstance(data, dict):
        raise ValueError(f"expected a mapping at the top, got {type(data).__name__}")
    if "value0" in data:  # TUM-VIE / Basalt JSON
        body = data["value0"]
        cameras = {str(k): (entry, body.get("resolution", [None] * (k + 1))[k])
                   for k, entry in enumerate(body["intrinsics"])}
        name, (entry, size) = _pick(cameras, camera, sensor_size, show, hidden)
        kind, values = entry["camera_type"], entry["intrinsics"]
        if kind not in ("kb4", "pinhole"):
            raise ValueError(f"value0.intrinsics[{name}].camera_type {show(kind)}: only kb4 and pinhole are "
                             "supported")
        coefficients = [values[k] for k in ("k1", "k2", "k3", "k4")] if kind == "kb4" else []
        return (intrinsics_from([values["fx"], values["fy"], values["cx"], values["cy"]], coefficients, "kb4", show),
                _size(size, show), f"camera {name} ({kind})")
    if "camera_matrix" in data and "image_width" in data:  # ROS camera_info
        k = _numbers(data["camera_matrix"]["data"], "camera_matrix.data", show)
        if len(k) != 9:
            raise ValueError(f"camera_matrix.data: expected 9 numbers (3x3), got {len(k)}")
        coefficients = (data.get("distortion_coefficients") or {}).get("data") or []
        model = data.get("distortion_model") or "plumb_bob"
        if model in ("plumb_bob", "radtan"):
            coefficients = list(coefficients)[:5]  # rational_polynomial is refused below, by name
        return (intrinsics_from([k[0], k[4], k[2], k[5]], coefficients, model, show),
                _size([data["image_width"], data["image_height"]], show),
                f"camera_info {_name(data.get('camera_name') or '', None)}".strip())
    if isinstance(data.get("intrinsics"), dict):  # DSEC cam_to_cam.yaml
        # The raw cameras first: the rectified camRectN (no distortion) only when asked for by name.
        entries = sorted(((name, entry) for name, entry in data["intrinsics"].items()
                          if isinstance(entry, dict) and "camera_matrix" in entry),
                         key=lambda item: str(item[0]).startswith("camRect"))
        cameras = {name: (entry, entry.get("resolution")) for name, entry in entries}
        name, (entry, size) = _pick(cameras, camera, sensor_size, show, hidden)
        return (intrinsics_from(entry["camera_matrix"], entry.get("distortion_coeffs", ()),
                                entry.get("distortion_model", "radtan"), show), _size(size, show),
                f"intrinsics.{_name(name, None)}")
    cameras = {name: (entry, entry.get("resolution")) for name, entry in data.items()
               if str(name).startswith("cam") and isinstance(entry, dict) and "intrinsics" in entry}
    if cameras:  # Kalibr camchain
        name, (entry, size) = _pick(cameras, camera, sensor_size, show, hidden)
        if entry.get("camera_model", "pinhole") != "pinhole":
            label = _name(name, hidden and f"camera {list(cameras).index(name)}")  # by position when hidden
            raise ValueError(f"{label}.camera_model {show(entry['camera_model'])}: only pinhole is supported")
        return (intrinsics_from(entry["intrinsics"], entry.get("distortion_coeffs", ()),
                                entry.get("distortion_model", "radtan"), show), _size(size, show), _name(name, None))
    raise ValueError("no camera found (no value0, camera_matrix, intrinsics or camN keys)")


def _pick(cameras: dict, camera, sensor_size, show: Callable[[object], str] = quote, hidden: str | None = None):
    if not cameras:
        raise ValueError("no camera with intrinsics in the file")
    if camera is not None:
        key = str(camera)
        if key not in cameras and key.isdigit() and int(key) < len(cameras):
            key = list(cameras)[int(key)]
        if key not in cameras:
            names = [_name(name, None) for name in list(cameras)[:12]]
            more = f" and {len(cameras) - 12} more" if len(cameras) > 12 else ""
            raise ValueError(f"no camera {quote(camera)}; the file has {hidden or ', '.join(names) + more}")
        return key, cameras[key]
    if sensor_size is not None:
        for key, (entry, size) in cameras.items():
            if size is not None and _size(size, show) == tuple(sensor_size):
                return key, (entry, size)
    key = next(iter(cameras))
    return key, cameras[key]


def _name(name: object, hidden: str | None) -> str:
    """A camera's name (a key of the file) in a message: as written when short, else cut to 40 characters;
    ``hidden`` when no field of the file may be shown (in errors: what a file that was read says of its
    camera is named as written)."""
    text = str(name)
    return hidden or (text if len(text) <= 40 and text.isprintable() else quote(text))


def _size(size, show: Callable[[object], str] = quote) -> tuple[int, int] | None:
    if size is None:
        return None
    out = []
    for value in list(size)[:2]:
        try:
            out.append(int(value))
        except (TypeError, ValueError, OverflowError):  # int()'s message quotes all of it
            raise ValueError(f"resolution: expected whole numbers, got {show(value)}") from None
    width, height = out
    return width, height


def check_camera_pick(calib: str | Path, what: str, where: str, option: str) -> None:
    """Refuse picking a camera (``option``, e.g. ``--camera`` or a plan's ``camera`` key) of a file that
    holds one (``what``, as ``read_camera_file`` says): one line starting with ``where``."""
    if what == "calib.txt" or what.startswith("camera_info"):
        raise DataError(f"{where}: {calib} holds one camera ({what}); {option} picks one of a file with several")


def set_camera(source, intrinsics: Intrinsics | None, calib: str | Path | None,
               camera: str | None) -> None:
    """Give ``source`` the camera of ``--intrinsics`` or ``--calib FILE`` (which win over the file's)."""
    if intrinsics is not None and calib is not None:
        raise DataError("--intrinsics and --calib: give one of them, not both")
    had = source.intrinsics is not None
    if calib is not None:
        intrinsics, size, what = read_camera_file(calib, camera, source.sensor_size)
        if camera is not None:
            check_camera_pick(calib, what, f"--camera {camera}", "--camera")
        if source.sensor_size is None and size is not None:
            source.sensor_size = size
            source.notes.append(f"sensor size {size[0]}x{size[1]} from {calib}")
        elif size is not None and tuple(size) != tuple(source.sensor_size):
            source.notes.append(f"{calib} ({what}) is a {size[0]}x{size[1]} camera's calibration, the recording's "
                                f"sensor is {source.sensor_size[0]}x{source.sensor_size[1]}: another camera? (--camera "
                                "picks one)")
        used = f"{calib} ({what})"
    else:
        used = "--intrinsics"
    source.intrinsics = intrinsics
    source.notes = [note for note in source.notes if note != NO_CALIBRATION]  # the camera is known now
    source.notes.append(f"intrinsics from {used}" + (", instead of the recording's" if had else ""))
