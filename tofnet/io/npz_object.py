"""One pickled Python object from a ``.npz`` member, without running code from the file.

Datasets store dictionaries of metadata as object arrays (``np.savez(..., meta=dict)``), which
``numpy.load`` reads only with ``allow_pickle=True``: a pickle can import and call anything. Here no
name the pickle gives is resolved to anything real: the four numpy names a 0-d object array needs
(its reconstructor, ``ndarray``, ``dtype``, the scalar constructor) are stand-ins that accept exactly
the arguments numpy writes for it (``dtype('O')``'s own state, shape ``()``, one object; a scalar of a
plain number type) and build no numpy object from the stream (a forged dtype or array could point
numpy at memory the file chooses, or allocate what it declares). Every other name is refused before
it is looked up. What comes out must be plain data (dict, list, tuple, str, bytes, int, float, bool,
None), walked without recursion and bounded in size. The member's bytes are bounded as for every
``.npz`` member (``tofnet.io.npy``). Errors are one line naming ``file[key]``.
"""

from __future__ import annotations

import ast
import io
import pickle
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from tofnet.errors import DataError, located, reason
from tofnet.io.files import open_regular
from tofnet.io.npy import MAGIC, MAX_HEADER_BYTES, MAX_INFLATE_RATIO, MAX_INFLATED_BYTES

#: The most values (dicts, lists, strings, numbers...) one pickled object may hold.
MAX_VALUES = 20_000_000
#: The dtypes a pickled object array may name: its own, and the plain numbers of numpy scalars inside it.
_DTYPES = ("O8", "f8", "f4", "f2", "i8", "i4", "i2", "i1", "u8", "u4", "u2", "u1", "b1")
_PLAIN = (dict, list, tuple, str, bytes, int, float, bool, type(None))


class _Refused(pickle.UnpicklingError):
    pass


class _Dtype:
    """``numpy.dtype(spec, False, True)`` as numpy pickles it, checked against numpy's own state for ``spec``."""

    def __init__(self, spec, align=False, copy=True):
        if spec not in _DTYPES or align is not False or copy is not True:
            raise _Refused(f"dtype {str(spec)[:20]!r}: only an object array of plain data is read")
        self.dtype = np.dtype(spec)

    def __setstate__(self, state) -> None:
        if state != self.dtype.__reduce__()[2]:
            raise _Refused(f"a dtype state other than numpy's for {self.dtype}")


class _Array:
    """A 0-d object array as numpy pickles it: ``_reconstruct(ndarray, (0,), b'b')`` then its state."""

    value = None

    def __setstate__(self, state) -> None:
        if (not isinstance(state, tuple) or len(state) != 5 or state[0] != 1 or state[1] != ()
                or not isinstance(state[2], _Dtype) or state[2].dtype != np.dtype("O") or state[3] is not False
                or not isinstance(state[4], list) or len(state[4]) != 1):
            raise _Refused("an array other than one object of shape ()")
        self.value = state[4][0]


_NDARRAY = object()  # what numpy.ndarray stands for: only an argument of _reconstruct


def _reconstruct(cls, shape, typecode) -> _Array:
    if cls is not _NDARRAY or shape != (0,) or typecode != b"b":
        raise _Refused("an array reconstructed otherwise than numpy pickles one")
    return _Array()


def _scalar(dtype, data) -> int | float | bool:
    """A numpy scalar of a plain number type, as the Python number it holds."""
    if not isinstance(dtype, _Dtype) or dtype.dtype.kind not in "biuf" or not isinstance(data, bytes) \
            or len(data) != dtype.dtype.itemsize:
        raise _Refused("a numpy scalar other than a plain number")
    return np.frombuffer(data, dtype=dtype.dtype)[0].item()


def _stand_ins() -> dict[tuple[str, str], object]:
    names = {("numpy", "ndarray"): _NDARRAY, ("numpy", "dtype"): _Dtype}
    for module in ("numpy.core.multiarray", "numpy._core.multiarray"):  # written by numpy 1.x and 2.x
        names[(module, "_reconstruct")] = _reconstruct
        names[(module, "scalar")] = _scalar
    return names


_ALLOWED = _stand_ins()


class _NumpyOnly(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        found = _ALLOWED.get((module, name))
        if found is None:
            raise _Refused(f"refers to {module}.{name}: not read (only numpy's own names are)")
        return found


def read_npz_object(path: str | Path, key: str) -> object:
    """The Python object (dict, list, str, numbers) stored as the 0-d object array ``key`` of the
    ``.npz`` file ``path``; ``DataError`` when it is absent, too large or holds anything else."""
    path = Path(path)
    source = f"{path}[{key}]"
    with open_regular(path, ".npz file") as handle:
        try:
            with zipfile.ZipFile(handle) as archive:
                info = next((i for i in archive.infolist() if i.filename == f"{key}.npy"), None)
                if info is None:
                    raise DataError(located(path, None, f"no array {key!r}"))
                if info.file_size > max(MAX_INFLATED_BYTES, MAX_INFLATE_RATIO * info.compress_size):
                    raise DataError(located(source, None, f"inflates to {info.file_size:,} bytes from "
                                                          f"{info.compress_size:,}: a zip bomb?"))
                data = archive.read(info)  # checks zip's CRC-32
        except (OSError, EOFError, zipfile.BadZipFile, zlib.error, ValueError, RuntimeError,
                NotImplementedError) as err:
            raise DataError(located(source, None, f"cannot read it: {reason(err)}")) from None
    stream = io.BytesIO(data)
    _object_header(stream, source)
    try:
        array = _NumpyOnly(stream).load()
    except Exception as err:  # pickle raises many kinds on a corrupt stream; none of it is run
        raise DataError(located(source, None, f"not a readable object array: {reason(err)}")) from None
    if not isinstance(array, _Array):
        raise DataError(located(source, None, "expected one pickled object (an object array of shape ())"))
    _check_plain(array.value, source)
    return array.value


def _check_plain(value: object, source: str) -> None:
    """Refuse anything but plain data in ``value`` (iteratively: a deep or shared structure costs no recursion)."""
    stack, seen, count = [value], set(), 0
    while stack:
        item = stack.pop()
        if not isinstance(item, _PLAIN):
            raise DataError(located(source, None, f"holds a {type(item).__name__}; expected plain data (dict, list, "
                                                  "str, numbers)"))
        if isinstance(item, (dict, list, tuple)):
            if id(item) in seen:
                continue
            seen.add(id(item))
            count += len(item)
            if count > MAX_VALUES:
                raise DataError(located(source, None, f"holds more than {MAX_VALUES:,} values"))
            stack.extend(item.keys() if isinstance(item, dict) else ())
            stack.extend(item.values() if isinstance(item, dict) else item)


def _object_header(stream: io.BytesIO, source: str) -> None:
    """Check the ``.npy`` header of a 0-d object array and leave ``stream`` at its pickle."""
    prefix = stream.read(8)
    if len(prefix) != 8 or prefix[:6] != MAGIC or prefix[6] not in (1, 2, 3):
        raise DataError(located(source, None, "not a valid .npy array: no .npy magic bytes or version"))
    size_bytes = stream.read(2 if prefix[6] == 1 else 4)
    length = struct.unpack("<H" if prefix[6] == 1 else "<I", size_bytes)[0] if len(size_bytes) in (2, 4) else -1
    if not 0 <= length <= MAX_HEADER_BYTES:
        raise DataError(located(source, None, "not a valid .npy array: its header's length"))
    try:
        header = ast.literal_eval(stream.read(length).decode("latin1"))
    except Exception:
        raise DataError(located(source, None, "not a valid .npy array: the header is not a Python literal")) from None
    if not isinstance(header, dict) or header.get("descr") != "|O" or header.get("shape") != ():
        raise DataError(located(source, None, "expected one pickled object (descr '|O', shape ())"))
