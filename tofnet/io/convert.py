"""Write a recording in another format: an ECD folder, ``.npz``, HDF5 (DSEC layout), AEDAT4,
Prophesee RAW (EVT3), Prophesee DAT (DAT2) or Event Stream (``.es``).

What the target cannot hold is either written as ECD side files next to it (AEDAT4, RAW,
DAT, Event Stream: ``calib.txt``, ``groundtruth.txt``; ``read_recording`` reads them back)
or reported in the returned messages; nothing is dropped without a line saying so. The
output appears under its final name only once complete (``tofnet.io.files``: written under
a temporary name, synced, then renamed), and is checked before any work
(``check_convert_output``). All but ECD and ``.npz`` are written chunk by chunk (bounded
memory); those two need the whole recording in memory.
"""

from __future__ import annotations

import os
from pathlib import Path

from tofnet.errors import DataError, located
from tofnet.io.source import DEFAULT_CHUNK, EventSource, ProgressHook

#: Output kinds by suffix; a name without suffix is an ECD folder.
OUTPUTS = {"": "ecd", ".npz": "npz", ".h5": "hdf5", ".hdf5": "hdf5", ".aedat4": "aedat4", ".raw": "evt3",
           ".dat": "dat", ".es": "es"}
#: Single-file kinds that get ECD side files (``calib.txt``, ``groundtruth.txt``) for the camera and poses.
_WITH_SIDE_FILES = ("aedat4", "evt3", "dat", "es")


#: The ECD side files written beside a file that cannot hold the camera or poses, and what each holds.
SIDE_FILES = {"calib.txt": "camera", "groundtruth.txt": "poses"}


def written_paths(out: str | Path) -> list[Path]:
    """Every path converting to ``out`` may write: the output, an ``.npz``'s true depth beside it,
    the side files beside a single file that cannot hold the camera or poses (an ECD folder: itself)."""
    out = Path(out)
    kind = output_kind(out)
    paths = [out]
    if kind == "npz":
        paths.append(_depth_path(out))
    if kind in _WITH_SIDE_FILES:
        paths += [out.parent / name for name in SIDE_FILES]
    return paths


def output_kind(out: str | Path) -> str:
    """``ecd``, ``npz``, ``hdf5``, ``aedat4``, ``evt3`` (``.raw``), ``dat`` or ``es`` from the output name;
    ``DataError`` otherwise."""
    suffix = Path(out).suffix.lower()
    if suffix not in OUTPUTS:
        raise DataError(located(out, None, f"cannot write {suffix!r}; expected a folder name (ECD), .npz, "
                                           ".h5/.hdf5 (DSEC layout), .aedat4, .raw (EVT3), .dat or .es"))
    return OUTPUTS[suffix]


#: Output kind -> the optional library its writer needs (``tofnet.io.extras``).
_WRITERS_NEED = {"aedat4": "faery", "hdf5": "h5py", "evt3": "faery", "dat": "faery", "es": "faery"}


def check_convert_output(out: str | Path, input_path: str | Path, *, force: bool = False,
                         gt_depth: bool = False) -> str:
    """Refuse, before any work, an output that cannot or must not be written (see
    ``tofnet.io.files.check_output``; an input is never overwritten, even with ``force``).
    Returns the output kind."""
    from tofnet.io.ecd import recording_files
    from tofnet.io.files import check_output

    out = Path(out)
    kind = output_kind(out)
    inputs = [Path(input_path), *recording_files(input_path)]
    check_output(out, force=force, inputs=inputs, what="output", folder=kind == "ecd")
    if gt_depth and kind == "npz":
        check_output(_depth_path(out), force=force, inputs=inputs, what="true depth output")
    from tofnet.io.guard import input_among

    for side in written_paths(out)[1:] if kind in _WITH_SIDE_FILES else ():
        if side.is_dir() and not side.is_symlink():
            raise DataError(located(side, None, "side file for the camera or poses: exists and is a folder"))
        # another recording's side file would be read with OUT as its camera or poses (an input's is its own)
        if os.path.lexists(side) and not force and input_among(side, inputs) is None:
            from tofnet.io.detect import event_files_in
            # the formats with no place for a camera or poses: they always read the side files (a .npz may be a
            # depth file, an .npy a true depth)
            others = [name for name in event_files_in(out.parent, suffixes=(".raw", ".dat", ".es", ".aedat4"))
                      if name != out.name]
            shared = (f"; {', '.join(others[:3])}{' ...' if len(others) > 3 else ''} here read"
                      f"{'s' if len(others) == 1 else ''} it too, and would with --force read the new one"
                      if others else "")
            raise DataError(located(side, None, f"exists, and {out.name} beside it would be read with it as its "
                                                f"camera or poses{shared}: convert into another folder, or --force "
                                                "to replace it"))
    if kind in _WRITERS_NEED:  # the writer's library, before anything is read or simulated
        from tofnet.io.extras import require
        require(_WRITERS_NEED[kind], out, f"writing {kind.upper()}")
    return kind


def _depth_path(out: Path) -> Path:
    return out.with_name(f"{out.stem}_depth.npy")


def convert(source: EventSource, out: str | Path, *, force: bool = False,
            progress: ProgressHook | None = None) -> list[str]:
    """Write ``source`` to ``out`` (format from its name); returns lines saying what went where."""
    from tofnet.io.files import atomic_path

    out = Path(out)
    kind = check_convert_output(out, source.path, force=force, gt_depth=source.has_depth)
    messages: list[str] = []
    if kind == "npz":  # written atomically by tofnet.io.npy
        from tofnet.io.arrays import write_npz_recording
        from tofnet.io.npy import write_npy
        meta = recording = source.read(progress)
        count = len(recording.events)
        write_npz_recording(out, recording)
        if recording.gt_depth is not None:
            write_npy(_depth_path(out), recording.gt_depth)
            messages.append(f"true depth per event -> {_depth_path(out)}")
    else:
        with atomic_path(out, folder=kind == "ecd", written_by="tofnet convert") as partial:
            if kind == "ecd":
                meta = recording = source.read(progress)
                count = len(recording.events)
                _write_ecd(partial, recording, messages)
            else:
                if kind in _WITH_SIDE_FILES and source.sensor_size is None:
                    source.sensor_size = _extent(source)
                    messages.append(f"sensor size {source.sensor_size[0]}x{source.sensor_size[1]} from the "
                                    "events' extent (the input does not say)")
                count = _writer(kind)(partial, source.chunks(DEFAULT_CHUNK, progress), source)
                meta = source
                if source.has_depth:
                    messages.append(f"not written: true depth per event ({kind} has no place for it)")
                if source.imu is not None and kind in ("evt3", "dat", "es"):  # known once the events are read
                    messages.append(f"not written: IMU ({len(source.imu):,} samples; {kind} has no place for it)")
            if count == 0:
                raise DataError(located(source.path, None, "no events"))
    if source.sensor_size is None:  # the input does not say (RAW, DAT, ES and AEDAT4 took the extent above)
        size = meta.sensor_size  # npz and ecd: the recording read whole, sized by its events' extent
        messages.append("not written: sensor size (the input does not say; read back, the events' extent gives it)"
                        if size is None else f"sensor size {size[0]}x{size[1]} from the events' extent (the input "
                        "does not say)")
    if kind in _WITH_SIDE_FILES:
        _side_files(out.parent, meta, messages, force, source.path)
    if source.unread:  # streams of the input tofnet does not read (AEDAT4's frames, an HDF5's images, a bag's topics)
        messages.append(f"not written: {'; '.join(source.unread)} (tofnet reads only the events, camera, poses and "
                        f"IMU of {source.path.name})")
    return [f"wrote {count:,} events to {out} ({kind})"] + messages


def _writer(kind: str):
    """The chunk writer of a file ``kind``: ``(path, chunks, meta) -> event count``."""
    if kind == "hdf5":
        from tofnet.io.hdf5 import write_hdf5
        return write_hdf5
    if kind == "aedat4":
        from tofnet.io.aedat import write_aedat4
        return write_aedat4
    from tofnet.io.prophesee_write import write_prophesee
    return lambda path, chunks, meta: write_prophesee(path, chunks, meta, kind)


def _write_ecd(folder: Path, recording, messages: list[str]) -> None:
    from tofnet.io.ecd import write_ecd

    intrinsics = _text_calibration(recording.intrinsics, messages)
    trajectory = recording.trajectory
    poses = (trajectory.times, trajectory.positions, trajectory.quaternions) \
        if trajectory is not None and hasattr(trajectory, "quaternions") else (None, None, None)
    write_ecd(folder, recording.events, intrinsics=intrinsics, times=poses[0], positions=poses[1],
              quaternions=poses[2], sensor_size=recording.sensor_size, gt_depth=recording.gt_depth)
    if recording.imu is not None:
        _write_imu(folder / "imu.txt", recording.imu)


def _text_calibration(intrinsics, messages: list[str]):
    """``intrinsics`` as ``calib.txt`` can hold them (radial-tangential or no distortion)."""
    if intrinsics is not None and intrinsics.distortion and intrinsics.distortion_model != "radtan":
        from dataclasses import replace
        messages.append(f"calib.txt holds radial-tangential distortion only: the {intrinsics.distortion_model} "
                        f"coefficients {intrinsics.distortion} are NOT written")
        intrinsics = replace(intrinsics, distortion=(), distortion_model="radtan")
    return intrinsics


def _write_imu(path: Path, imu) -> None:
    from tofnet.io.groundtruth import _write_rows  # the shared exact-float table writer

    _write_rows(path, imu, "# t ax ay az gx gy gz  (s, m/s², rad/s)")


def _side_files(folder: Path, meta, messages: list[str], force: bool, input_path: Path) -> None:
    """ECD ``calib.txt``/``groundtruth.txt`` next to a file that cannot hold them (never over an input)."""
    from tofnet.io.calibration import write_calibration
    from tofnet.io.ecd import recording_files
    from tofnet.io.groundtruth import write_groundtruth
    from tofnet.io.guard import input_among

    writes = []
    intrinsics = _text_calibration(meta.intrinsics, messages)
    if intrinsics is not None:
        writes.append(("calib.txt", lambda p: write_calibration(p, intrinsics)))
    if meta.trajectory is not None and hasattr(meta.trajectory, "quaternions"):
        t = meta.trajectory
        writes.append(("groundtruth.txt", lambda p: write_groundtruth(p, t.times, t.positions, t.quaternions)))
    inputs = [input_path, *recording_files(input_path)]
    for name, write in writes:
        if input_among(folder / name, inputs) is not None:
            messages.append(f"NOT written: {folder / name} is an input of this conversion")
            continue
        write(folder / name)
        messages.append(f"{name.split('.')[0]} -> {folder / name} (read back as a side file)")
    written = {name for name, _ in writes}
    for name, what in SIDE_FILES.items():
        # with --force another recording's side file passed the check; nothing of the input's replaced it
        if name not in written and os.path.lexists(folder / name) and input_among(folder / name, inputs) is None:
            messages.append(f"NOTE: {folder / name} is not this input's (it has no {what}) and stays: it will be "
                            f"read as the {what} of what was written beside it; move it away if it is not")


def _extent(source: EventSource) -> tuple[int, int]:
    from tofnet.events import sensor_size_problem

    width = height = 0
    for chunk in source.chunks():
        width, height = max(width, int(chunk["x"].max()) + 1), max(height, int(chunk["y"].max()) + 1)
    problem = sensor_size_problem(width, height)
    if problem:
        raise DataError(located(source.path, None, f"sensor size not in the file, and the events' extent is not "
                                                   f"a usable one: {problem} (pass --sensor-size)"))
    return width, height
