"""Which dataset sequence layout a folder is in (DSEC, MVSEC, TUM-VIE, M3ED, EVIMO2), from the files it holds,
and the sequence's name; reading them is ``tofnet.io.sequences``'s."""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import DataError, located

#: Folder layouts ``detect_format`` recognises, with a one-line description.
SEQUENCE_FORMATS = {
    "dsec": "DSEC sequence folder (events/left/events.h5, calibration/cam_to_cam.yaml, disparity/)",
    "mvsec": "MVSEC sequence folder (*_data.hdf5, *_gt.hdf5, *_calib/camchain-imucam-*.yaml)",
    "tumvie": "TUM-VIE sequence folder (*-events_left.h5, calibration JSON, mocap_data.txt)",
    "m3ed": "M3ED sequence folder (*_data.h5, *_depth_gt.h5)",
    "evimo2": "EVIMO2 v2 sequence folder (dataset_events_{t,xy,p}.npy, dataset_info.npz, dataset_depth.npz)",
}
SIDES = ("left", "right")
#: EVIMO2's event cameras: the folder three levels above a sequence's.
EVIMO2_CAMERAS = ("samsung_mono", "left_camera", "right_camera")


def sequence_kind(folder: Path) -> str | None:
    """The key of ``SEQUENCE_FORMATS`` for a folder, ``None`` when it is none of them (an ECD folder)."""
    if (folder / "events" / "left" / "events.h5").exists() or (folder / "events" / "right" / "events.h5").exists():
        return "dsec"
    if (folder / "calibration" / "cam_to_cam.yaml").exists() or (folder / "disparity").is_dir():
        raise DataError(located(folder / "events" / "left" / "events.h5", None,
                                "missing: a DSEC sequence folder needs its events (events/left/events.h5 "
                                "or events/right/events.h5)"))
    return other_kind(folder)


def sequence_name(path: str | Path) -> str | None:
    """The sequence a folder or events file belongs to (its folder's name), ``None`` for other paths.

    ``<seq>/events/left/events.h5`` -> ``seq`` (``seq-right`` for the right camera);
    ``<seq>_data.hdf5`` (MVSEC), ``<seq>_data.h5`` (M3ED), ``<seq>-events_left.h5`` (TUM-VIE) -> ``seq``;
    EVIMO2's ``<camera>/<category>/<subcategory>/<seq>/`` -> ``seq-camera`` (its three cameras share sequence names).
    """
    path = Path(path)
    if path.name == "events.h5" and path.parent.name in SIDES and path.parent.parent.name == "events":
        folder = path.parent.parent.parent.resolve()
        return folder.name + ("-right" if path.parent.name == "right" else "")
    for ending in ("_data.hdf5", "_data.h5", "-events_left.h5"):
        if path.name.endswith(ending) and len(path.name) > len(ending):
            return path.name[:-len(ending)]
    if path.is_dir():
        folder = path.resolve()
        camera = evimo2_camera(folder) if (folder / "dataset_info.npz").exists() else ""
        return f"{folder.name}-{camera}" if camera else folder.name
    return None


def evimo2_camera(folder: Path) -> str:
    """The EVIMO2 camera of a sequence folder (``<camera>/<category>/<subcategory>/<seq>``), "" when it is not under
    one of ``EVIMO2_CAMERAS``."""
    parents = Path(folder).resolve().parents
    return parents[2].name if len(parents) > 2 and parents[2].name in EVIMO2_CAMERAS else ""


def dsec_sequence_of(path: Path) -> tuple[Path, str] | None:
    """``(sequence folder, side)`` for ``<seq>/events/{left,right}/events.h5`` beside
    ``<seq>/calibration/cam_to_cam.yaml`` (read as the whole sequence), else ``None``."""
    path = Path(path)
    if path.name != "events.h5" or path.parent.name not in SIDES or path.parent.parent.name != "events":
        return None
    folder = path.parent.parent.parent
    if not (folder / "calibration" / "cam_to_cam.yaml").exists():
        return None
    return folder, path.parent.name


#: Each layout's events file pattern.
PATTERNS = {"mvsec": "*_data.hdf5", "m3ed": "*_data.h5", "tumvie": "*-events_left.h5"}


def other_kind(folder: Path) -> str | None:
    """``mvsec``, ``tumvie``, ``m3ed`` or ``evimo2`` for a folder of that layout, else ``None``."""
    if (folder / "dataset_events_t.npy").exists() or (folder / "dataset_info.npz").exists():
        return "evimo2"
    for kind, pattern in PATTERNS.items():
        if matches(folder, pattern) or (kind == "tumvie" and matches(folder, "*-events_right.h5")):
            return kind
    return None


def matches(folder: Path, pattern: str) -> list[Path]:
    """The files of ``folder`` matching ``pattern``, sorted; one that is not a regular file (a FIFO, a
    folder) is a one-line error naming it, not passed over (``tofnet.io.files.present``)."""
    from tofnet.io.files import present

    return sorted(p for p in folder.glob(pattern) if present(p, f"a regular file ({pattern}: a sequence's events)"))
