"""Fuzz targets for what a file may say about where its data is (issue 27): HDF5 external
storage, virtual datasets, links and declared sizes; ROS message definitions and stamps.

A case is a small *recipe*, lines of whole numbers that each pick an option, so that the
fuzzer's edits (a number replaced by a hostile token, a line cut or doubled) pick other
options instead of only breaking the syntax. The target builds the files the recipe
describes in the scratch folder (h5py, rosbags' writer), reads them as a user would, and
knows which of them must be refused: an accepted result that should have been refused
is ``Invalid``. A word that is not a number picks by its length; a recipe that the
libraries cannot build is a clean ``DataError`` ("not a case").

HDF5 recipe: ``allow A`` (``allow_external``), ``store K`` (what an external raw file is:
``STORES``), then per column ``t``/``x``/``y``/``p``: ``MODE A B`` (``MODES``; ``A``, ``B``
sizes or offsets). ROS recipe: ``ts``, ``x``, ``y``, ``polarity`` (a field type, index 0
is the standard one), ``extra`` (an added field), ``md5`` (0: the text's own md5sum,
1: the standard md5sum whatever the text, else garbage), ``nsec`` (added to the first
event's nanoseconds).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tofnet.errors import DataError
from tofnet.fuzzing_checks import check_recording, require
from tofnet.fuzzing_sessions import check_replayed, number as _number, run_session, session_seeds

MODES = ("plain", "external", "virtual", "declared", "group", "compressed", "link", "dev-zero")
STORES = ("regular", "fifo", "dev-zero", "missing", "short", "folder")
_TIMES = np.array([1000, 1500, 2000, 2000, 3500, 9000], dtype="<i8")
_COLUMNS = {"t": _TIMES, "x": np.array([1, 2, 3, 15, 0, 7], "<u2"), "y": np.array([2, 2, 2, 11, 0, 5], "<u2"),
            "p": np.array([1, 0, 1, 1, 0, 0], "u1")}
_TS_TYPES = ("time", "int64", "uint64", "float64", "duration", "uint32")
_XY_TYPES = ("uint16", "int16", "uint32", "uint8")
_POLARITY_TYPES = ("bool", "uint8", "int8", "uint16")


@dataclass
class Outcome:
    """What the reader returned, and why it should have refused (None: it may accept)."""

    recording: Any
    must_refuse: str | None


def check_outcome(result: Outcome) -> None:
    require(result.must_refuse is None, f"accepted although {result.must_refuse}")
    check_recording(result.recording)


def _recipe(data: bytes) -> dict[str, list[int]]:
    out: dict[str, list[int]] = {}
    for line in data.decode("utf-8", "replace").splitlines():
        words = line.split()
        if words:
            out.setdefault(words[0], [_number(w) for w in words[1:]])
    return out


def _pick(values: list[int], i: int, default: int = 0) -> int:
    return values[i] if i < len(values) else default


# ---------------------------------------------------------------- HDF5

def _clear(folder: Path) -> None:
    """Remove what an earlier case built in the scratch folder (FIFOs and links included)."""
    for entry in folder.iterdir():
        if entry.is_dir() and not entry.is_symlink():
            entry.rmdir()
        else:
            entry.unlink()


def _hdf5(data: bytes, folder: Path) -> Outcome:
    import h5py

    from tofnet.io import read_recording

    _clear(folder)
    recipe = _recipe(data)
    allow = bool(_pick(recipe.get("allow", []), 0))
    store = STORES[_pick(recipe.get("store", []), 0) % len(STORES)]
    path, reasons = folder / "rec.h5", []
    try:
        with h5py.File(folder / "src.h5", "w") as source:
            for name, values in _COLUMNS.items():
                source[name] = values
        with h5py.File(path, "w") as out:
            for name, values in _COLUMNS.items():
                words = recipe.get(name, [0])
                problem = _column(out, folder, name, values, MODES[_pick(words, 0) % len(MODES)],
                                  _pick(words, 1), _pick(words, 2), store)
                if problem == "elsewhere":
                    problem = None if allow else "its data is in another file and allow_external is off"
                reasons.append(problem)
            out["t_offset"] = np.int64(0)
    except (OSError, ValueError, TypeError, KeyError, RuntimeError, OverflowError) as err:
        raise DataError(f"not a case: {type(err).__name__}") from None
    recording = read_recording(path, allow_external=allow)
    return Outcome(recording, next((r for r in reasons if r), None))


def _column(out, folder: Path, name: str, values: np.ndarray, mode: str, a: int, b: int, store: str) -> str | None:
    """Write column ``name`` as ``mode``; why a reader must refuse it ("elsewhere": unless allowed)."""
    import h5py

    key = f"events/{name}"
    if mode == "plain":
        out[key] = values
    elif mode == "compressed":
        out.create_dataset(key, data=values, compression="gzip", chunks=(max(1, min(a, 1 << 16)),))
    elif mode == "group":
        out.create_group(key)
        return "a group stands where a dataset is expected"
    elif mode == "declared":
        n = min(a, 10**13)
        chunked = b % 2 == 0 and n > 0
        out.create_dataset(key, shape=(n,), dtype=values.dtype, chunks=(min(n, 1 << 12),) if chunked else None)
        return "its storage was never written" if n else None
    elif mode in ("external", "dev-zero"):
        raw = f"{name}.raw" if mode == "external" else "/dev/zero"
        needed, offset = values.nbytes, b % 64
        out.create_dataset(key, shape=values.shape, dtype=values.dtype,
                           external=[(raw, offset, needed + a % 64)])
        if mode == "dev-zero":
            return "its storage is /dev/zero"
        held = _store(folder / raw, values, offset, store)
        return "elsewhere" if held >= needed else f"its external storage is {store}"
    elif mode == "virtual":
        source = ("src.h5", "missing.h5", "src.h5")[b % 3]
        layout = h5py.VirtualLayout(shape=values.shape, dtype=values.dtype)
        layout[:] = h5py.VirtualSource(source, name if b % 3 != 2 else "absent", shape=values.shape)
        out.create_virtual_dataset(key, layout, fillvalue=0)
        return "elsewhere" if b % 3 == 0 else "its virtual source is missing"
    elif mode == "link":
        out[key] = h5py.ExternalLink("src.h5" if b % 2 == 0 else "missing.h5", f"/{name}")
        return "elsewhere" if b % 2 == 0 else "its external link points to a missing file"
    return None


def _store(raw: Path, values: np.ndarray, offset: int, kind: str) -> int:
    """Create the external raw file as ``kind``; the bytes it holds for the dataset."""
    if kind == "fifo":
        os.mkfifo(raw)
    elif kind == "dev-zero":
        raw.symlink_to("/dev/zero")
    elif kind == "folder":
        raw.mkdir()
    elif kind in ("regular", "short"):
        data = b"\0" * offset + values.tobytes()
        raw.write_bytes(data if kind == "regular" else data[:len(data) // 2])
        return len(data) - offset if kind == "regular" else -1
    return -1


def _hdf5_seeds() -> list[bytes]:
    return [b"allow 0\nstore 0\nt 0 0 0\nx 0 0 0\ny 0 0 0\np 0 0 0\n",
            b"allow 1\nstore 0\nt 1 0 0\nx 0 0 0\ny 2 0 0\np 5 4 0\n",
            b"allow 1\nstore 0\nt 6 0 0\nx 1 3 8\ny 0 0 0\np 0 0 0\n"]


# ---------------------------------------------------------------- ROS message definitions

def _rosbag(data: bytes, folder: Path) -> Outcome:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from tofnet.io import read_recording
    from tofnet.io.rosbag import typestore

    _clear(folder)
    recipe = _recipe(data)
    picks = {key: _pick(recipe.get(key, []), 0) for key in ("ts", "x", "y", "polarity", "extra", "md5", "nsec")}
    event = (f"{_XY_TYPES[picks['x'] % 4]} x\n{_XY_TYPES[picks['y'] % 4]} y\n{_TS_TYPES[picks['ts'] % 6]} ts\n"
             f"{_POLARITY_TYPES[picks['polarity'] % 4]} polarity\n" + ("uint8 extra\n" if picks["extra"] % 3 == 1 else ""))
    array = "std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n" + \
        ("float32 extra\n" if picks["extra"] % 3 == 2 else "")
    standard = typestore()
    expected_md5 = standard.generate_msgdef("dvs_msgs/msg/EventArray", ros_version=1)[1]
    try:
        claimed = get_typestore(Stores.ROS1_NOETIC)
        claimed.register({**get_types_from_msg(event, "dvs_msgs/msg/Event"),
                          **get_types_from_msg(array, "dvs_msgs/msg/EventArray")})
        text, text_md5 = claimed.generate_msgdef("dvs_msgs/msg/EventArray", ros_version=1)
        md5 = (text_md5, expected_md5, "0" * 32)[min(picks["md5"], 2)]
        types, stamp = standard.types, standard.types["builtin_interfaces/msg/Time"]
        nsec = [int(t) % 10**6 * 1000 for t in _TIMES]
        nsec[0] += picks["nsec"]
        message = types["dvs_msgs/msg/EventArray"](
            header=types["std_msgs/msg/Header"](seq=0, stamp=stamp(sec=0, nanosec=0), frame_id="dvs"),
            height=12, width=16,
            events=[types["dvs_msgs/msg/Event"](x=int(x), y=int(y), ts=stamp(sec=int(t) // 10**6, nanosec=ns),
                                                polarity=bool(p))
                    for t, x, y, p, ns in zip(_TIMES, _COLUMNS["x"], _COLUMNS["y"], _COLUMNS["p"], nsec)])
        raw = standard.serialize_ros1(message, "dvs_msgs/msg/EventArray")  # the standard bytes, always
        with Writer(folder / "rec.bag") as writer:
            connection = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", msgdef=text, md5sum=md5)
            writer.write(connection, 1_000_000, raw)
    except Exception as err:  # noqa: BLE001 - rosbags' own checks on the recipe: not a case
        raise DataError(f"not a case: {type(err).__name__}") from None
    recording = read_recording(folder / "rec.bag")
    reason = None
    if text_md5 != expected_md5:
        reason = "its message definition is not the standard one"
    elif md5 != expected_md5:
        reason = "its md5sum is not the standard one"
    elif nsec[0] >= 10**9:
        reason = f"an event's nanoseconds are {nsec[0]}"
    return Outcome(recording, reason)


def _rosbag_seeds() -> list[bytes]:
    return [b"ts 0\nx 0\ny 0\npolarity 0\nextra 0\nmd5 0\nnsec 0\n", b"ts 0\nmd5 1\nnsec 999\n"]


def random_recipe(rng, name: str) -> bytes:
    """A recipe of target ``name`` with every option drawn at random (``rng``: ``random.Random``)."""
    if name == "hdf5 storage":
        lines = [f"allow {rng.randint(0, 1)}", f"store {rng.randrange(len(STORES))}"]
        lines += [f"{column} {rng.randrange(len(MODES)) if rng.random() < 0.4 else 0} {rng.choice((0, 3, 6, 64, 10**12))} "
                  f"{rng.randrange(70)}" for column in _COLUMNS]
    elif name == "session":
        lines = [" ".join([rng.choice(("feed", "feed", "feed", "set", "monitor", "run"))] +
                          [str(rng.randrange(400)) for _ in range(3)]) for _ in range(rng.randint(1, 10))]
    else:
        lines = [f"{key} {rng.randrange(8) if rng.random() < 0.3 else 0}" for key in ("ts", "x", "y", "polarity", "extra")]
        lines += [f"md5 {rng.randrange(3)}", f"nsec {rng.choice((0, 999, 10**9 - 10**6, 10**9, 3 * 10**9))}"]
    return ("\n".join(lines) + "\n").encode()


#: Target name -> (run, check, seeds, the library it needs); the session target is ``tofnet.fuzzing_sessions``'s.
STORAGE_TARGETS = {"hdf5 storage": (_hdf5, check_outcome, _hdf5_seeds, "h5py"),
                   "ros definitions": (_rosbag, check_outcome, _rosbag_seeds, "rosbags"),
                   "session": (run_session, check_replayed, session_seeds, "numpy")}


def storage_seeds(name: str) -> list[bytes]:
    """Valid recipes of target ``name`` (none when its library is not installed)."""
    import importlib.util

    _, _, make, library = STORAGE_TARGETS[name]
    return make() if importlib.util.find_spec(library) is not None else []


__all__ = ["STORAGE_TARGETS", "storage_seeds", "random_recipe", "check_outcome", "Outcome"]
