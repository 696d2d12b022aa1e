"""Options that say how to read an input recording, shared by ``run``, ``info``, ``convert``
(all of them) and ``export``, ``eval`` (the time window)."""

from __future__ import annotations

import argparse

from tofnet.errors import TofnetError


def add_input_options(p: argparse.ArgumentParser) -> None:
    """``--columns`` for plain numpy arrays, ``--topic ROLE=NAME`` for ROS bags, ``--allow-external`` for HDF5."""
    g = p.add_argument_group("input")
    g.add_argument("--columns", metavar="ORDER",
                   help="column order of a plain (n, 4) numpy array, e.g. x,y,t,p (default t,x,y,p); "
                        "a float t is seconds, an integer t microseconds")
    g.add_argument("--topic", action="append", default=[], metavar="ROLE=NAME",
                   help="ROS bag topic for a role (events, pose, imu, camera_info), "
                        "e.g. --topic events=/davis/left/events; repeatable (default: found by message type)")
    add_allow_external(g)
    add_camera_options(p)
    add_window_options(p)
    add_sequence_options(p)


def add_sequence_options(p: argparse.ArgumentParser) -> None:
    """``--side`` and ``--rectify`` for dataset sequence folders (DSEC, MVSEC, TUM-VIE, M3ED)."""
    g = p.add_argument_group("dataset sequence folders")
    g.add_argument("--side", choices=("left", "right"),
                   help="which event camera of a DSEC, MVSEC, TUM-VIE or M3ED sequence folder (default left)")
    g.add_argument("--rectify", action="store_true",
                   help="DSEC: move the events through events/SIDE/rectify_map.h5 (the rectified camera, as the "
                        "disparity ground truth); default: raw pixels, the ground truth looked up through the map")


def sequence_options(args) -> dict:
    """``side`` and ``rectify`` for ``open_recording``."""
    return {"side": getattr(args, "side", None), "rectify": bool(getattr(args, "rectify", False))}


def add_allow_external(p) -> None:
    """``--allow-external``: the opt-in for HDF5 data kept in other files (``open_recording``'s ``allow_external``)."""
    p.add_argument("--allow-external", action="store_true",
                   help="read HDF5 datasets whose data is in other files (external storage, virtual datasets, "
                        "external links); refused by default")


def add_camera_options(p: argparse.ArgumentParser) -> None:
    """``--intrinsics`` or ``--calib FILE`` (``--camera``): the camera when the recording has none (or another)."""
    g = p.add_argument_group("camera")
    g.add_argument("--intrinsics", metavar="FX,FY,CX,CY[,K1,K2,P1,P2[,K3]]",
                   help="camera intrinsics in pixels, with radtan distortion (as calib.txt); instead of the "
                        "recording's or a calib.txt beside it")
    g.add_argument("--calib", metavar="FILE",
                   help="calibration file: ECD calib.txt, Kalibr or DSEC camera YAML (cam_to_cam.yaml), "
                        "TUM-VIE calibration JSON or ROS camera_info YAML")
    g.add_argument("--camera", metavar="NAME",
                   help="which camera of a --calib file with several (cam3, or an index); default: the first "
                        "whose resolution is the recording's sensor size, else the first")


def camera_options(args) -> dict:
    """``intrinsics``, ``calib``, ``camera`` for ``open_recording`` from the parsed options."""
    from tofnet.io.calibration import parse_intrinsics

    text = getattr(args, "intrinsics", None)
    if getattr(args, "camera", None) and not getattr(args, "calib", None):
        raise TofnetError("--camera picks a camera of a --calib file; give --calib FILE")
    return {"intrinsics": parse_intrinsics(text) if text else None, "calib": getattr(args, "calib", None),
            "camera": getattr(args, "camera", None)}


def add_window_options(p: argparse.ArgumentParser) -> None:
    """``--start``, ``--duration``, ``--until``: read only a time window of the recording."""
    g = p.add_argument_group("time window")
    g.add_argument("--start", metavar="T",
                   help="first time to read: seconds from the recording's first event (12.5s, 500ms, 12.5) "
                        "or absolute on the file's clock (@1627000012.5s); default: the first event")
    g.add_argument("--duration", metavar="T", help="length of the window (2s, 500ms); default: to the end")
    g.add_argument("--until", metavar="T", help="end of the window (excluded), as --start; instead of --duration")


def window_option(args):
    """The ``TimeWindow`` of ``--start/--duration/--until``, or ``None``."""
    from tofnet.io.window import parse_window
    return parse_window(getattr(args, "start", None), getattr(args, "duration", None), getattr(args, "until", None))


def sensor_size_option(args) -> tuple[int, int] | None:
    """``--sensor-size WxH`` (pixels) as ``open_recording``'s ``sensor_size``, None when not given."""
    from tofnet.core.params import parse_size
    return parse_size(args.sensor_size, "--sensor-size") if getattr(args, "sensor_size", None) else None


def input_options(args) -> dict:
    """Keyword arguments for ``read_recording``/``open_recording`` from the parsed options."""
    topics = {}
    for item in getattr(args, "topic", None) or []:
        role, sep, name = item.partition("=")
        if not sep or not role or not name:
            raise TofnetError(f"--topic: expected ROLE=NAME (e.g. events=/dvs/events), got {item!r}")
        topics[role.strip()] = name.strip()
    return {"columns": getattr(args, "columns", None), "topics": topics or None, "window": window_option(args),
            "allow_external": bool(getattr(args, "allow_external", False)), **camera_options(args),
            **sequence_options(args)}
