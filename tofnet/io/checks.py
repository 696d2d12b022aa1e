"""The checks every reader shares (docs/reliability.md), made once in ``tofnet.io.source``.

- ``check_metadata``: what a file declares — sensor size within ``MAX_SENSOR_SIDE`` and
  ``MAX_SENSOR_PIXELS``, finite intrinsics with ``fx``, ``fy`` >= 1 px, IMU rows;
- ``check_packet``: every event a reader returns — ``|t| < MAX_TIME_US``, whole
  coordinates 0..65535 — before it is copied into a chunk;
- ``decode_errors``: which exceptions of a decoding library (h5py, faery, rosbags) mean
  "bad file" and become a one-line ``DataError``.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from tofnet.errors import DataError, located, quote
from tofnet.events import MAX_TIME_US, sensor_size_problem
from tofnet.io.calibration import IntrinsicsError, check_intrinsics


#: What decoding libraries raise on a bad file (h5py: OSError, KeyError, ValueError,
#: TypeError; faery: RuntimeError; numpy on cut buffers: ValueError; rosbags: ReaderError, SerdeError).
_LIBRARY_ERRORS = (OSError, EOFError, ValueError, KeyError, TypeError, IndexError, RuntimeError, OverflowError,
                   struct.error, zlib.error)
#: Formats tofnet parses itself: a stray exception there is a bug to fix, not translated.
OWN_FORMATS = ("ecd", "text", "npy", "npz")


def decode_errors(kind: str) -> tuple[type[BaseException], ...]:
    """The exceptions that mean "bad file" when the library of format ``kind`` raises them."""
    if kind in OWN_FORMATS:
        return ()
    errors = _LIBRARY_ERRORS
    if kind in ("rosbag1", "rosbag2"):
        errors += (AssertionError,)  # rosbags checks some record fields with assert
        try:
            from rosbags.rosbag1 import ReaderError
            from rosbags.rosbag2 import ReaderError as Reader2Error
            from rosbags.serde import SerdeError  # a message that does not deserialise
            errors += (ReaderError, Reader2Error, SerdeError)
            import sqlite3

            import apsw  # rosbags reads .db3 through apsw too
            errors += (sqlite3.Error, apsw.Error)  # a .db3 that is not (or no longer) a rosbag2 database
            if kind == "rosbag2":  # rosbags' MCAP reader reads a record's stated length at once
                errors += (MemoryError,)
        except ImportError:
            pass
    return errors


def is_decode_error(err: BaseException, kind: str) -> bool:
    """Whether ``err``, raised while the library of format ``kind`` read a file, means
    "bad file": one of ``decode_errors(kind)``, or a Rust panic of faery surfacing as
    pyo3's ``PanicException`` (a ``BaseException``, importable only once raised)."""
    if kind in OWN_FORMATS:
        return False
    return isinstance(err, decode_errors(kind)) or type(err).__name__ == "PanicException"


def check_packet(packet: np.ndarray, first_index: int, path: object) -> None:
    """Refuse events outside the documented ranges before they are copied into a chunk.

    Times must satisfy ``|t| < MAX_TIME_US`` (compared in the reader's own dtype, so a
    ``uint64`` past ``2**63`` does not wrap negative first) and be integers (µs); ``x``,
    ``y`` must fit ``uint16``. ``first_index`` is the packet's first event in the file.
    """
    names = packet.dtype.names
    if names is None or len(names) < 4:
        raise DataError(located(path, None, f"the reader returned events without fields t, x, y, p "
                                            f"({packet.dtype}); this is a bug of tofnet's reader"))
    if len(packet) == 0:
        return
    t = packet[names[0]]
    if t.dtype.kind not in "iu":
        raise DataError(located(path, None, f"event times must be whole microseconds, got dtype {t.dtype}"))
    high = t.max() >= MAX_TIME_US
    low = t.dtype.kind == "i" and t.min() <= -MAX_TIME_US
    if high or low:
        i = int(np.flatnonzero((t >= MAX_TIME_US) | ((t <= -MAX_TIME_US) if t.dtype.kind == "i" else False))[0])
        raise DataError(located(path, None, f"event {first_index + i + 1:,}: time {int(t[i])} µs is out of range "
                                            f"(|t| < 2**61 µs)"))
    for name, values in (("x", packet[names[1]]), ("y", packet[names[2]])):
        if values.dtype in (np.uint8, np.uint16):
            continue
        if values.dtype.kind not in "iu" or values.min() < 0 or values.max() > 65535:
            bad = np.flatnonzero((values < 0) | (values > 65535) | (values != np.floor(values)))
            i = int(bad[0]) if bad.size else 0
            raise DataError(located(path, None, f"event {first_index + i + 1:,}: {name} = {values[i]}; expected a "
                                                "whole pixel coordinate 0..65535"))


def check_metadata(source, path: object) -> None:
    """The checks on what a file declares, shared by every reader (``source`` is an
    ``EventSource`` or a ``Recording``): the sensor size (``sensor_size_problem``), the
    intrinsics (finite, ``fx``, ``fy`` >= 1 px, 5 radtan or 4 equidistant coefficients or
    none) and the IMU (``(n, 7)`` finite rows, times in range and not decreasing)."""
    size = source.sensor_size
    if size is not None:
        try:
            width, height = (int(v) for v in size)
        except (TypeError, ValueError, OverflowError):
            raise DataError(located(path, None, f"sensor size: expected (width, height) in pixels, got "
                                                f"{quote(size)}")) from None
        problem = sensor_size_problem(width, height)
        if problem:
            raise DataError(located(path, None, f"sensor size: {problem}"))
        source.sensor_size = (width, height)
    intrinsics = source.intrinsics
    if intrinsics is not None:
        values = (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy, *intrinsics.distortion)
        if not all(isinstance(v, (int, float, np.floating, np.integer)) for v in values):
            raise DataError(located(path, None, "intrinsics: expected numbers fx fy cx cy and distortion"))
        try:  # the one rule for what no camera has, as every camera file is read with
            check_intrinsics(*values[:4], tuple(values[4:]))
        except IntrinsicsError as err:
            raise DataError(located(path, None, f"intrinsics: {err}")) from None
        expected = {"radtan": 5, "equidistant": 4}.get(intrinsics.distortion_model)
        if expected is None or len(intrinsics.distortion) not in (0, expected):
            raise DataError(located(path, None, f"intrinsics: {len(intrinsics.distortion)} distortion coefficients "
                                                f"for model {str(intrinsics.distortion_model)[:20]!r}; expected 5 "
                                                "radtan (k1 k2 p1 p2 k3) or 4 equidistant (k1 k2 k3 k4)"))
    imu = source.imu
    if imu is not None:
        imu = np.asarray(imu)
        if imu.ndim != 2 or imu.shape[1] != 7 or imu.dtype.kind not in "iuf":
            raise DataError(located(path, None, f"IMU: expected rows t ax ay az gx gy gz (n, 7), got shape "
                                                f"{imu.shape} and dtype {imu.dtype}"))
        imu = imu.astype(np.float64)
        bad = np.flatnonzero(~np.all(np.isfinite(imu), axis=1) | (np.abs(imu[:, 0]) >= MAX_TIME_US * 1e-6))
        if bad.size:
            raise DataError(located(path, None, f"IMU sample {int(bad[0])}: expected finite values and "
                                                "|t| < 2**61 µs"))
        back = np.flatnonzero(np.diff(imu[:, 0]) < 0)
        if back.size:
            raise DataError(located(path, None, f"IMU sample {int(back[0]) + 1}: time goes back; samples must be "
                                                "sorted by time"))
        source.imu = imu
