"""How a plan's recordings are read: the plan keys that are ``tofnet run``'s input options.

``intrinsics``, ``calib``, ``camera``, ``velocity``, ``columns``, ``topics``, ``start``,
``duration``, ``until``, ``side``, ``rectify`` (dataset sequence folders) may be given plan-wide (top level) or on a path or glob entry (which
wins, key by key). They are checked when the plan loads, with the same parsers as the
command line, and kept as plain values (a calibration file as an absolute path), so a
task carries them to its worker and its id changes when they do.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

from tofnet.errors import TofnetError

#: The reading keys, in the order they are shown.
READ_KEYS = ("intrinsics", "calib", "camera", "velocity", "columns", "topics", "start", "duration", "until", "side",
             "rectify")


def read_options(entry: Mapping, defaults: dict[str, Any], where: str,
                 fail: Callable[[Mapping, str, str, str], Exception], resolve: Callable[[str], Path]) -> dict[str, Any]:
    """``defaults`` updated with the reading keys of ``entry``, each checked; ``fail(entry, key, path,
    message)`` builds the plan error naming the line and the key."""
    from tofnet.io.arrays import parse_columns
    from tofnet.io.calibration import parse_intrinsics, read_camera_file
    from tofnet.io.window import parse_window

    options = dict(defaults)
    for key in READ_KEYS:
        if key not in entry:
            continue
        value, path = entry[key], f"{where}{key}"
        try:
            if key == "topics":
                if not isinstance(value, Mapping) or not value or \
                        not all(isinstance(k, str) and isinstance(v, str) and v.strip() for k, v in value.items()):
                    raise TofnetError("expected a mapping ROLE: TOPIC (events, pose, imu, camera_info)")
                from tofnet.io.rosbag import ROLES
                unknown = sorted(set(value) - set(ROLES))
                if unknown:
                    raise TofnetError(f"unknown role {unknown[0]!r}; expected {', '.join(ROLES)}")
                value = {str(k): str(v) for k, v in value.items()}
            elif key == "side":
                if value not in ("left", "right"):
                    raise TofnetError(f"expected left or right, got {value!r}")
            elif key == "rectify":
                if not isinstance(value, bool):
                    raise TofnetError(f"expected true or false, got {value!r}")
            elif key in ("start", "duration", "until"):
                if isinstance(value, bool) or not isinstance(value, (str, int, float)):
                    raise TofnetError(f"expected a time like 12.5s, 500ms or @1627000012.5s, got {value!r}")
                value = str(value)
            else:
                if isinstance(value, list) and key in ("intrinsics", "velocity", "columns"):
                    value = ",".join(str(v) for v in value)
                if not isinstance(value, (str, int)) or isinstance(value, bool) or not str(value).strip():
                    raise TofnetError(f"expected a string, got {value!r}")
                value = str(value)
                if key == "intrinsics":
                    parse_intrinsics(value, "")
                elif key == "calib":
                    calib = resolve(value)
                    read_camera_file(calib, entry.get("camera", defaults.get("camera")))
                    value = str(calib)
                elif key == "velocity":
                    velocity(value)
                elif key == "columns":
                    parse_columns(value, "")
        except TofnetError as err:
            message = str(err) if key == "calib" else str(err).removeprefix(": ").removeprefix(f"{key}: ")
            raise fail(entry, key, path, message) from None
        options[key] = value
    if "intrinsics" in options and "calib" in options:
        key = "calib" if "calib" in entry else "intrinsics"
        raise fail(entry, key, f"{where}{key}",
                   "intrinsics and calib: give one of them, not both")
    if "camera" in entry and "calib" not in options:
        raise fail(entry, "camera", f"{where}camera", "picks a camera of a calib file; give calib: FILE")
    if options.get("camera") is not None and options.get("calib") and ("camera" in entry or "calib" in entry):
        from tofnet.io.calibration import check_camera_pick
        key = "camera" if "camera" in entry else "calib"
        try:
            check_camera_pick(options["calib"], read_camera_file(options["calib"], options["camera"])[2],
                              str(options["camera"]), "camera")
        except TofnetError as err:
            raise fail(entry, key, f"{where}{key}", str(err)) from None
    if "duration" in options and "until" in options:
        key = "until" if "until" in entry else "duration"
        raise fail(entry, key, f"{where}{key}", "duration and until: give one of them, not both")
    window_keys = [k for k in ("start", "duration", "until") if k in options]
    if window_keys:
        try:
            parse_window(options.get("start"), options.get("duration"), options.get("until"),
                         names=("start", "duration", "until"))
        except TofnetError as err:
            key = next((k for k in reversed(window_keys) if k in entry), window_keys[-1])
            raise fail(entry, key, f"{where}{key}", str(err)) from None
    return options


def velocity(text: str) -> tuple[float, float, float]:
    """``TX,TY,TZ`` m/s (camera frame), each finite."""
    import math

    try:
        values = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise TofnetError(f"expected TX,TY,TZ in m/s (camera frame), got {text!r}")
    return values  # type: ignore[return-value]


def open_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """Keyword arguments for ``read_recording``/``open_recording`` (``velocity`` is the network's)."""
    from tofnet.io.calibration import parse_intrinsics
    from tofnet.io.window import parse_window

    return {"columns": options.get("columns"), "topics": options.get("topics"),
            "intrinsics": parse_intrinsics(options["intrinsics"]) if options.get("intrinsics") else None,
            "calib": options.get("calib"), "camera": options.get("camera"),
            "window": parse_window(options.get("start"), options.get("duration"), options.get("until")),
            "side": options.get("side"), "rectify": bool(options.get("rectify", False))}
