"""An open recording: its metadata at once, its events in time-ordered chunks of bounded size.

``open_recording(path)`` returns an ``EventSource`` for any format ``detect_format``
knows. Its attributes (``sensor_size``, ``intrinsics``, ``trajectory``, ``imu``,
``n_events``, ``streams``, ``notes``) come from the file's header or index (and from
ECD side files next to it for what the file lacks) without decoding the events;
``chunks(n)`` then yields ``EVENT_DTYPE`` arrays of ``n`` events (the last one shorter),
holding at most about one chunk in memory, and ``read()`` loads everything into a
``Recording``, which is what ``read_recording`` does.

The checks of docs/reliability.md are made here once for every format: what a file
declares (``check_metadata``: sensor size within ``MAX_SENSOR_SIDE``/``MAX_SENSOR_PIXELS``,
finite intrinsics with ``fx``, ``fy`` >= 1 px, IMU rows) when it is opened and once more
after ``read()``; every event a reader returns (``check_packet``: ``|t| < MAX_TIME_US``,
coordinates 0..65535) before it is copied into a chunk; and errors of the decoding
libraries (h5py, faery, rosbags) become one-line ``DataError``s.

A time window (``open_recording(..., window=)``, ``set_window``; ``tofnet.io.window``)
makes ``chunks`` and ``read`` give only its events, found through the file's own index
where it has one; recordings parsed whole live in ``tofnet.io.in_memory``.
"""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import DataError, located, reason
from tofnet.events import sensor_size_problem
from tofnet.io.checks import OWN_FORMATS, check_metadata, is_decode_error
from tofnet.io.event_source import DEFAULT_CHUNK, EventSource, ProgressHook  # noqa: F401 (the API's names)
from tofnet.io.recording import Intrinsics


def fill_from_side_files(source: EventSource) -> EventSource:
    """Take from ECD side files next to ``source.path`` what the file itself does not hold.

    ``calib.txt`` (intrinsics), ``groundtruth.txt`` (poses), ``imu.txt`` and
    ``sensor_size.txt``; the file's own values win. Each one used is noted.
    """
    from tofnet.io.calibration import read_calibration
    from tofnet.io.ecd import CALIBRATION, GROUNDTRUTH, IMU, SENSOR_SIZE, read_imu, read_sensor_size
    from tofnet.io.groundtruth import read_groundtruth

    folder = source.path.parent
    for name, attribute, reader in ((CALIBRATION, "intrinsics", read_calibration),
                                    (GROUNDTRUTH, "trajectory", read_groundtruth),
                                    (IMU, "imu", read_imu), (SENSOR_SIZE, "sensor_size", read_sensor_size)):
        # A side file that exists but is not a regular file is an error (the reader says so).
        if getattr(source, attribute) is None and ((folder / name).exists() or (folder / name).is_symlink()):
            setattr(source, attribute, reader(folder / name))
            source.notes.append(f"{attribute.replace('_', ' ')} from {name} next to the file")
    return source


def open_recording(path: str | Path, *, sensor_size: tuple[int, int] | None = None,
                   columns: str | tuple[str, ...] | None = None,
                   topics: dict[str, str] | None = None, window=None, intrinsics: Intrinsics | None = None,
                   calib: str | Path | None = None, camera: str | None = None,
                   allow_external: bool = False, side: str | None = None, rectify: bool = False,
                   reading_size: tuple[int, int] | None = None) -> EventSource:
    """Open any recording ``detect_format`` knows; see the module docstring.

    ``sensor_size`` (width, height px) overrides the file's; ``reading_size`` (px) is a sensor the events may
    fill (``tofnet run --sensor-size``: the network's) while the file's size stays: a reader that refuses pixels
    beyond its header's geometry (EVT3) reads up to it; ``columns`` gives the column
    order of a plain ``(n, 4)`` numpy array (e.g. ``"x,y,t,p"``); ``topics`` overrides the
    ROS bag topics found automatically (keys ``events``, ``pose``, ``imu``, ``camera_info``);
    ``window`` (a ``tofnet.io.window.TimeWindow``) reads only the events of that time window;
    ``intrinsics``, or a calibration file ``calib`` (``read_camera_file``; ``camera`` picks one of
    several), replace the recording's camera (the image size of the file fills a missing sensor size).
    ``allow_external`` lets an HDF5 file keep data in other files (external storage,
    virtual datasets, external links; refused otherwise). ``side`` (left, right) and ``rectify`` apply to
    dataset sequence folders (``tofnet.io.sequences``).
    """
    from tofnet.io.detect import detect_format
    from tofnet.io.layouts import SEQUENCE_FORMATS, dsec_sequence_of

    path = Path(path)
    kind = detect_format(path)
    if columns is not None and kind not in ("npy", "npz"):
        raise DataError(located(path, None, f"--columns applies to plain numpy arrays (.npy/.npz), not {kind} files"))
    if topics and kind not in ("rosbag1", "rosbag2"):
        raise DataError(located(path, None, f"topics apply to ROS bags, not {kind} files"))
    sequence = dsec_sequence_of(path) if kind == "hdf5" else None  # <seq>/events/SIDE/events.h5: the whole sequence
    if sequence is not None:
        if side is not None and side != sequence[1]:
            raise DataError(located(path, None, f"--side {side}: the file is the {sequence[1]} camera's"))
        kind, path, side = "dsec", *sequence
    if (side is not None and kind not in SEQUENCE_FORMATS and kind != "hdf5") or (rectify and kind not in SEQUENCE_FORMATS):
        raise DataError(located(path, None, "--side and --rectify apply to dataset sequence folders (DSEC, MVSEC, "
                                            f"TUM-VIE, M3ED), not {kind} recordings"))
    try:
        if kind in SEQUENCE_FORMATS:
            from tofnet.io.sequences import open_sequence
            source = open_sequence(path, kind, side=side, rectify=rectify, allow_external=allow_external)
        elif kind in ("aedat4", "evt", "dat", "es"):
            from tofnet.io.prophesee import open_faery
            source = open_faery(path, kind)
        elif kind == "hdf5":
            from tofnet.io.hdf5_open import open_hdf5
            source = open_hdf5(path, allow_external, side or "left")
        elif kind in ("rosbag1", "rosbag2"):
            from tofnet.io.rosbag import RosbagSource
            source = RosbagSource(path, topics, kind)
        else:
            from tofnet.io.in_memory import RecordingSource, read_in_memory
            recording, span = read_in_memory(path, kind, columns, window)
            source = RecordingSource(recording, kind, path, span)
    except BaseException as err:
        if not is_decode_error(err, kind):
            raise
        raise DataError(located(path, None, f"not a readable {FORMAT_NAMES.get(kind, kind)} file: "
                                            f"{reason(err)}")) from None
    try:
        if kind not in OWN_FORMATS and kind not in SEQUENCE_FORMATS:
            fill_from_side_files(source)
        if kind == "hdf5":  # an MVSEC or TUM-VIE file: the calibration its dataset ships beside it
            from tofnet.io.sequences_other import complete_file
            complete_file(source, side or "left")
        for given in (sensor_size, reading_size):
            if given is not None:
                problem = sensor_size_problem(*(int(v) for v in given))
                if problem:
                    raise DataError(f"sensor size: {problem}")
        if sensor_size is not None:
            stated, source.sensor_size = source.sensor_size, tuple(int(v) for v in sensor_size)
            if stated is not None and tuple(stated) != source.sensor_size:
                source.notes.append(f"sensor size {source.sensor_size[0]}x{source.sensor_size[1]} px given, over the "
                                    f"{stated[0]}x{stated[1]} px the file states")
        if reading_size is not None:
            source.reading_size = tuple(int(v) for v in reading_size)
        if intrinsics is not None or calib is not None:
            from tofnet.io.calibration import set_camera
            set_camera(source, intrinsics, calib, camera)
        check_metadata(source, path)
        from tofnet.io.plausible import plausibility_notes
        found = plausibility_notes(source)  # another clock, unit or camera? (before a window cuts the poses)
        source.notes.extend(note for _, note, _ in found)
        source.doubts = [(topic, note) for topic, note, loud in found if loud]
        if window is not None:
            source.set_window(window)
    except BaseException as err:
        source.close()
        if not is_decode_error(err, kind):
            raise
        raise DataError(located(path, None, f"not a readable {FORMAT_NAMES.get(kind, kind)} file: "
                                            f"{reason(err)}")) from None
    return source


#: Format names for messages.
FORMAT_NAMES = {"aedat4": "AEDAT4", "evt": "Prophesee RAW", "dat": "Prophesee DAT", "es": "Event Stream",
                "hdf5": "HDF5", "rosbag1": "ROS1 bag",
                "rosbag2": "ROS 2 bag"}
