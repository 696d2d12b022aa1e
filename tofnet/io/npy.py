"""Reading ``.npy`` and ``.npz`` files without trusting them.

``numpy.load`` allocates whatever a header declares, tokenizes corrupt headers with
errors of its own, and inflates any zip member in full. Here, before a byte of data is
allocated:
- the header is parsed as a literal (``ast.literal_eval``, at most ``MAX_HEADER_BYTES``)
  and must hold ``descr``, ``fortran_order`` and ``shape``; object dtypes are refused;
- ``shape x itemsize`` must equal the bytes the file (or zip member) actually holds;
- a zip member may inflate to at most ``max(MAX_INFLATED_BYTES, MAX_INFLATE_RATIO x its
  compressed size)``, which refuses zip bombs (deflate reaches ~1000x on constant data);
- a member is read to its end, so zip's CRC-32 is checked, and a truncated ``.npz``
  (no central directory) is refused.
Every problem is a one-line ``DataError``. Limits are documented in docs/reliability.md.
"""

from __future__ import annotations

import ast
import os
import struct
import zipfile
import zlib
from pathlib import Path
from typing import IO, Callable, Iterable

import numpy as np

from tofnet.errors import DataError, located, reason
from tofnet.io.files import open_regular

MAGIC = b"\x93NUMPY"
ZIP_MAGIC = b"PK\x03\x04"
#: Longest ``.npy`` header read (numpy writes < 200 bytes; numpy's own limit is 10,000).
MAX_HEADER_BYTES = 10_000
#: A zip member inflating to more than this must also be at most ``MAX_INFLATE_RATIO``
#: times its compressed size.
MAX_INFLATED_BYTES = 256 * 2**20
MAX_INFLATE_RATIO = 100
_READ_CHUNK = 16 * 2**20
_ERRORS = (OSError, EOFError, zipfile.BadZipFile, zlib.error, ValueError, RuntimeError, NotImplementedError)


def _read_exactly(stream: IO[bytes], n: int) -> bytes:
    data = stream.read(n)
    if len(data) != n:
        raise EOFError(f"ended after {len(data)} of {n} bytes")
    return data


def _read_header(stream: IO[bytes], source: object) -> tuple[tuple[int, ...], bool, np.dtype, int]:
    """``(shape, fortran_order, dtype, header_bytes)`` of the ``.npy`` data at ``stream``."""
    def corrupt(why: str) -> DataError:
        return DataError(located(source, None, f"not a valid .npy array: {why}"))

    try:
        prefix = _read_exactly(stream, 8)
    except EOFError:
        raise corrupt("the file ends inside the header") from None
    if prefix[:6] != MAGIC:
        raise corrupt("no .npy magic bytes")
    major = prefix[6]
    if major not in (1, 2, 3):
        raise corrupt(f"unknown format version {major}.{prefix[7]}")
    try:
        size_bytes = _read_exactly(stream, 2 if major == 1 else 4)
        length = struct.unpack("<H" if major == 1 else "<I", size_bytes)[0]
        if length > MAX_HEADER_BYTES:
            raise corrupt(f"a header of {length:,} bytes (at most {MAX_HEADER_BYTES:,} accepted)")
        raw = _read_exactly(stream, length)
    except EOFError:
        raise corrupt("the file ends inside the header") from None
    try:
        header = ast.literal_eval(raw.decode("utf-8" if major == 3 else "latin1"))
    except Exception:  # literal_eval raises SyntaxError, ValueError, MemoryError, RecursionError, ...
        raise corrupt("the header is not a Python literal") from None
    if not isinstance(header, dict) or set(header) != {"descr", "fortran_order", "shape"}:
        raise corrupt("the header must hold exactly descr, fortran_order and shape")
    shape, fortran = header["shape"], header["fortran_order"]
    if (not isinstance(shape, tuple) or len(shape) > 32
            or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape)):
        raise corrupt("shape must be a tuple of whole numbers >= 0")
    if not isinstance(fortran, bool):
        raise corrupt("fortran_order must be True or False")
    try:
        dtype = np.lib.format.descr_to_dtype(header["descr"])
    except Exception:
        raise corrupt("descr is not a numpy dtype") from None
    if dtype.hasobject:
        raise DataError(located(source, None, "holds Python objects (pickled data), which are not read"))
    if dtype.itemsize == 0 and dtype.names is None:
        raise corrupt(f"dtype {dtype} has no size")
    return shape, fortran, dtype, len(prefix) + len(size_bytes) + length


def _read_array(stream: IO[bytes], total: int, source: object) -> np.ndarray:
    """The array of a ``.npy`` stream of ``total`` bytes; its size is checked before allocating."""
    shape, fortran, dtype, header_bytes = _read_header(stream, source)
    count = 1
    for n in shape:
        count *= n
    declared, held = count * dtype.itemsize, total - header_bytes
    if declared != held:
        what = "is truncated" if declared > held else "has extra bytes"
        raise DataError(located(source, None, f"{what}: the header declares {declared:,} bytes of data "
                                              f"(shape {shape}, {dtype.itemsize} bytes each), the file holds {held:,}"))
    array = np.empty(count, dtype=dtype)
    if declared:
        buffer = memoryview(array.view(np.uint8).reshape(-1))
        done = 0
        while done < declared:
            got = stream.readinto(buffer[done:done + _READ_CHUNK])
            if not got:
                raise DataError(located(source, None, f"is truncated: ended after {done:,} of {declared:,} bytes"))
            done += got
    if fortran:
        return array.reshape(shape[::-1]).transpose()
    return array.reshape(shape)


def load_npy(path: str | Path, what: str = ".npy file") -> np.ndarray:
    """The array in a ``.npy`` file (see the module's checks)."""
    path = Path(path)
    with open_regular(path, what) as handle:
        size = os.fstat(handle.fileno()).st_size
        try:
            return _read_array(handle, size, path)
        except _ERRORS as err:
            raise DataError(located(path, None, f"cannot read the array: {reason(err)}")) from None


def map_npy(path: str | Path, what: str = ".npy file") -> np.ndarray:
    """The array of a ``.npy`` file as a read-only memory map, after the same header and size checks
    as ``load_npy``: nothing is read until it is indexed (time windows read only their rows)."""
    path = Path(path)
    with open_regular(path, what) as handle:
        size = os.fstat(handle.fileno()).st_size
        try:
            shape, fortran, dtype, header_bytes = _read_header(handle, path)
        except _ERRORS as err:
            raise DataError(located(path, None, f"cannot read the array: {reason(err)}")) from None
    count = 1
    for n in shape:
        count *= n
    if count * dtype.itemsize != size - header_bytes:
        with open_regular(path, what) as handle:  # the same message as load_npy
            _read_array(handle, size, path)
    if count == 0:
        return np.empty(shape, dtype=dtype)
    return np.memmap(path, dtype=dtype, mode="r", offset=header_bytes, shape=shape, order="F" if fortran else "C")


def load_npz(path: str | Path, wanted: Iterable[str] | None = None,
             what: str = ".npz file") -> tuple[list[str], dict[str, np.ndarray]]:
    """The keys of a ``.npz`` file and the arrays of those in ``wanted`` (all when None)."""
    path = Path(path)
    with open_regular(path, what) as handle:
        try:
            archive = zipfile.ZipFile(handle)
        except _ERRORS as err:
            raise DataError(located(path, None, f"not a readable .npz (zip) file, or truncated ({reason(err)})")) from None
        with archive:
            members = {info.filename[:-4]: info for info in archive.infolist() if info.filename.endswith(".npy")}
            keys = list(members)
            arrays = {}
            for key in keys if wanted is None else [k for k in wanted if k in members]:
                arrays[key] = _read_member(archive, members[key], f"{path}[{key}]")
    return keys, arrays


def npz_shape(path: str | Path, key: str, what: str = ".npz file") -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype of the array ``key`` of a ``.npz`` file, from its header alone (nothing else is inflated)."""
    path = Path(path)
    with open_regular(path, what) as handle:
        try:
            with zipfile.ZipFile(handle) as archive:
                info = next((i for i in archive.infolist() if i.filename == f"{key}.npy"), None)
                if info is None:
                    raise DataError(located(path, None, f"no array {key!r}"))
                with archive.open(info) as stream:
                    shape, _, dtype, _ = _read_header(stream, f"{path}[{key}]")
        except _ERRORS as err:
            raise DataError(located(path, None, f"not a readable .npz (zip) file, or truncated ({reason(err)})")) from None
    return shape, dtype


def _read_member(archive: zipfile.ZipFile, info: zipfile.ZipInfo, source: str) -> np.ndarray:
    limit = max(MAX_INFLATED_BYTES, MAX_INFLATE_RATIO * info.compress_size)
    if info.file_size > limit:
        raise DataError(located(source, None, f"inflates to {info.file_size:,} bytes from {info.compress_size:,} "
                                              f"(more than {MAX_INFLATE_RATIO}x past {MAX_INFLATED_BYTES // 2**20} MiB: "
                                              "a zip bomb?); save large arrays uncompressed (np.savez) or as .npy"))
    try:
        with archive.open(info) as stream:
            array = _read_array(stream, info.file_size, source)
            if stream.read(1):  # also completes zip's CRC-32 check
                raise DataError(located(source, None, "holds more bytes than the zip directory declares"))
    except _ERRORS as err:
        raise DataError(located(source, None, f"cannot read the array: {reason(err)}")) from None
    return array


def numpy_kind(path: str | Path, what: str = "numpy file") -> str:
    """``"npy"`` or ``"npz"``, told apart by the file's first bytes (not its name)."""
    path = Path(path)
    with open_regular(path, what) as handle:
        start = handle.read(6)
    if start == MAGIC:
        return "npy"
    if start[:4] in (ZIP_MAGIC, b"PK\x05\x06"):
        return "npz"
    raise DataError(located(path, None, "not a readable .npy/.npz file (neither magic bytes found)"))


#: The time stamped on every member of the ``.npz`` files tofnet writes (numpy's own writer
#: stamps the wall-clock time, so the same arrays written twice would differ in bytes).
ZIP_TIME = (1980, 1, 1, 0, 0, 0)


class Column:
    """A one-dimensional array written piece by piece: ``length`` values of ``dtype`` that
    ``pieces()`` yields in order (so a column larger than memory can be written)."""

    def __init__(self, dtype, length: int, pieces: Callable[[], Iterable[np.ndarray]]):
        self.dtype, self.length, self.pieces = np.dtype(dtype), int(length), pieces


def write_npz(path: str | Path, arrays: dict[str, "np.ndarray | Column"], compress: bool = False) -> None:
    """Write ``arrays`` as a ``.npz`` atomically (see ``tofnet.io.files.atomic_write``), the same
    bytes for the same arrays: a zip of ``name.npy`` members (numpy's format, readable by
    ``np.load``) with a fixed time stamp, in the order given. A ``Column`` is written as it
    comes, in bounded memory."""
    from tofnet.io.files import atomic_write
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with atomic_write(path) as handle:
        with zipfile.ZipFile(handle, "w", compression=method, allowZip64=True) as archive:
            for name, array in arrays.items():
                info = zipfile.ZipInfo(f"{name}.npy", date_time=ZIP_TIME)
                info.compress_type = method
                info.external_attr = 0o644 << 16
                with archive.open(info, "w", force_zip64=True) as member:
                    if isinstance(array, Column):
                        _write_column(member, array)
                    else:
                        np.lib.format.write_array(member, np.asanyarray(array), allow_pickle=False)


def _write_column(member: IO[bytes], column: Column) -> None:
    header = {"descr": np.lib.format.dtype_to_descr(column.dtype), "fortran_order": False,
              "shape": (column.length,)}
    np.lib.format.write_array_header_1_0(member, header)
    written = 0
    for piece in column.pieces():
        piece = np.ascontiguousarray(piece, dtype=column.dtype)
        member.write(piece.tobytes())
        written += len(piece)
    if written != column.length:
        raise ValueError(f"column yielded {written} values, {column.length} declared")


def write_npy(path: str | Path, array: np.ndarray) -> None:
    """Write one array as ``.npy`` atomically."""
    from tofnet.io.files import atomic_write
    with atomic_write(path) as handle:
        np.save(handle, array, allow_pickle=False)


__all__ = ["load_npy", "load_npz", "numpy_kind", "write_npz", "write_npy",
           "MAX_HEADER_BYTES", "MAX_INFLATED_BYTES", "MAX_INFLATE_RATIO"]
