"""Optional dependencies: which ``pip install "tofnet[extra]"`` brings the library a file needs."""

from __future__ import annotations

import importlib
from types import ModuleType

from tofnet.errors import DataError, located

#: Import name -> (extra that installs it, what it reads).
EXTRAS = {
    "faery": ("formats", "AEDAT4, Prophesee RAW (EVT2/EVT3) and DAT, Event Stream files"),
    "h5py": ("hdf5", "HDF5 files (DSEC, TUM-VIE, MVSEC, M3ED layouts)"),
    "hdf5plugin": ("hdf5plugin", "compressed HDF5 datasets (Blosc, Zstandard, LZ4, ...)"),
    "rosbags": ("ros", "ROS1 and ROS 2 bags"),
}


def require(module: str, path: object, what: str | None = None) -> ModuleType:
    """Import ``module`` or raise a one-line ``DataError`` naming the extra to install for ``path``
    (``what``: what needs it, e.g. "writing AEDAT4"; default: reading the files it reads)."""
    try:
        return importlib.import_module(module)
    except ImportError:
        extra, reads = EXTRAS[module]
        raise DataError(located(path, None, f"{what or 'reading ' + reads} needs the '{extra}' extra: "
                                            f"pip install \"tofnet[{extra}]\" (provides {module})")) from None


def available(module: str) -> bool:
    """Whether ``module`` can be imported (without raising)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True
