"""One pickled Python object from a ``.npz`` member, without running code from the file.

Datasets store dictionaries of metadata as object arrays (``np.savez(..., meta=dict)``), which
``numpy.load`` reads only with ``allow_pickle=True``: a pickle can import and call anything.
Here the pickle stream is read by an unpickler that resolves exactly the four numpy names an
object array needs (its reconstructor, ``ndarray``, ``dtype`` and the scalar constructor);
any other name (``os.system``, ``builtins.eval``, a class of the sender's) is refused before it
is looked up, so nothing the file names is imported or called. The member's size is bounded
as for every ``.npz`` member (``tofnet.io.npy``). Errors are one line naming ``file[key]``.
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


def _numpy_names() -> dict[tuple[str, str], object]:
    try:
        from numpy._core import multiarray  # numpy >= 2
    except ImportError:  # pragma: no cover - numpy 1.x
        from numpy.core import multiarray
    names = {}
    for module in ("numpy.core.multiarray", "numpy._core.multiarray"):  # written by numpy 1.x and 2.x
        names[(module, "_reconstruct")] = multiarray._reconstruct
        names[(module, "scalar")] = multiarray.scalar
    names[("numpy", "ndarray")] = np.ndarray
    names[("numpy", "dtype")] = np.dtype
    return names


_ALLOWED = _numpy_names()


class _NumpyOnly(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        found = _ALLOWED.get((module, name))
        if found is None:
            raise pickle.UnpicklingError(f"refers to {module}.{name}: not read (only numpy's own names are)")
        return found


def read_npz_object(path: str | Path, key: str):
    """The Python object (dict, list, str, numbers) stored as the 0-d object array ``key`` of the
    ``.npz`` file ``path``; ``DataError`` when it is absent, too large or names anything else."""
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
    if not isinstance(array, np.ndarray) or array.dtype != object or array.shape != ():
        raise DataError(located(source, None, "expected one pickled object (an object array of shape ())"))
    return array.item()


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
