"""Open an HDF5 event file with the reader of its layout: DSEC/TUM-VIE/tofnet (``tofnet.io.hdf5``),
MVSEC or M3ED (``tofnet.io.hdf5_datasets``). Above both readers, so neither imports the other's
registry."""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import DataError, located, quote, reason
from tofnet.io.event_source import EventSource
from tofnet.io.extras import require
from tofnet.io.hdf5 import DsecSource
from tofnet.io.hdf5_checks import H5File
from tofnet.io.hdf5_datasets import M3edSource, MvsecSource


def open_hdf5(path: Path, allow_external: bool = False, side: str = "left") -> EventSource:
    """The reader for the layout found in ``path``; ``DataError`` naming the groups otherwise.

    ``side``: the camera of an MVSEC (``davis/SIDE``) or M3ED (``prophesee/SIDE``) file.

    ``allow_external``: read datasets whose data is in other files (external storage,
    virtual datasets, external links), each checked (``tofnet.io.hdf5_checks``)."""
    h5py = require("h5py", path)
    try:
        handle = h5py.File(path, "r")
    except OSError as err:
        raise DataError(located(path, None, f"not a readable HDF5 file ({reason(err)})")) from None
    h5 = H5File(handle, path, allow_external)
    try:
        if _has(h5, "events", ("x", "y", "t", "p")):
            return DsecSource(path, h5)
        if "davis/left/events" in h5:
            return MvsecSource(path, h5, side)
        if _has(h5, "prophesee/left", ("x", "y", "t", "p")):
            return M3edSource(path, h5, side)
        keys = h5.keys()
        found = ", ".join(quote(key, 20) for key in keys[:10]) + (", ..." if len(keys) > 10 else "") or "nothing"
        raise DataError(located(path, None, f"no event datasets; expected events/{{x,y,t,p}} (DSEC, TUM-VIE), "
                                            f"davis/left/events (MVSEC) or prophesee/left/{{x,y,t,p}} (M3ED); "
                                            f"found {found}"))
    except BaseException:
        handle.close()
        raise


def _has(h5: H5File, group: str, names: tuple[str, ...]) -> bool:
    return group in h5 and all(f"{group}/{name}" in h5 for name in names)
