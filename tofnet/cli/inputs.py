"""Options that say how to read an input recording, shared by ``run``, ``info`` and ``convert``."""

from __future__ import annotations

import argparse

from tofnet.errors import TofnetError


def add_input_options(p: argparse.ArgumentParser) -> None:
    """``--columns`` for plain numpy arrays and ``--topic ROLE=NAME`` for ROS bags."""
    g = p.add_argument_group("input")
    g.add_argument("--columns", metavar="ORDER",
                   help="column order of a plain (n, 4) numpy array, e.g. x,y,t,p (default t,x,y,p); "
                        "a float t is seconds, an integer t microseconds")
    g.add_argument("--topic", action="append", default=[], metavar="ROLE=NAME",
                   help="ROS bag topic for a role (events, pose, imu, camera_info), "
                        "e.g. --topic events=/davis/left/events; repeatable (default: found by message type)")


def input_options(args) -> dict:
    """Keyword arguments for ``read_recording``/``open_recording`` from the parsed options."""
    topics = {}
    for item in getattr(args, "topic", None) or []:
        role, sep, name = item.partition("=")
        if not sep or not role or not name:
            raise TofnetError(f"--topic: expected ROLE=NAME (e.g. events=/dvs/events), got {item!r}")
        topics[role.strip()] = name.strip()
    return {"columns": getattr(args, "columns", None), "topics": topics or None}
