"""What an HDF5 file declares, checked before libhdf5 reads a byte of data.

An HDF5 file can keep a dataset's bytes outside itself: *external raw storage* (any file,
a FIFO, ``/dev/zero``), a *virtual dataset* (slices of datasets in other files; a missing
source reads as fill values), an *external link* (an object in another file). It can also
declare a dataset far larger than the bytes it holds (unallocated storage reads as fill
values: a 9 KB file can declare 10^12 events). ``H5File`` is the one way tofnet's readers
reach a dataset, and refuses all of these with one line:

- external storage, virtual datasets and external links unless ``allow_external``; even
  then every file they name must lie in the HDF5 file's folder or below it (links resolved;
  an absolute path too) and be a regular file holding the bytes, and every virtual source
  dataset must exist;
- a dataset whose allocated storage is less than its declared shape needs (contiguous:
  fewer bytes; chunked: a chunk never written; compressed: more than
  ``max(MAX_INFLATED_BYTES, MAX_INFLATE_RATIO x stored)``, the ``.npz`` rule);
- a group where a dataset is expected, and a dataset where a group is;
- a compression filter h5py lacks without ``hdf5plugin``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from tofnet.errors import DataError, located
from tofnet.io.extras import require
from tofnet.io.files import lies_in, open_regular
from tofnet.io.npy import MAX_INFLATE_RATIO, MAX_INFLATED_BYTES

#: Filters every h5py build has: deflate, shuffle, fletcher32, szip, nbit, scaleoffset, lzf.
_BUILTIN_FILTERS = {1, 2, 3, 4, 5, 6, 32000}
#: Soft links followed while checking a path before refusing it as a loop.
_MAX_LINKS = 16
#: What the opt-in is called, for messages.
ALLOW = "--allow-external (allow_external=True in Python)"


class H5File:
    """An open ``h5py.File`` whose datasets and groups are reached only through these checks.

    ``path``: the file's name for messages (and the folder external files are found in).
    """

    def __init__(self, handle, path: Path, allow_external: bool = False):
        self.handle, self.path, self.allow_external = handle, Path(path), bool(allow_external)

    def _fail(self, message: str) -> DataError:
        return DataError(located(self.path, None, message))

    # -- names ------------------------------------------------------------------------------
    def _link(self, name: str, depth: int = 0) -> str | None:
        """The object ``name`` reaches, as an absolute path in this file after soft links (None:
        absent), checking every external link on the way (they open another file)."""
        import h5py

        parts, done = [p for p in name.split("/") if p], ""
        for k, part in enumerate(parts):
            where = f"{done}/{part}"
            try:
                link = self.handle.get(where, getlink=True)
            except (KeyError, ValueError, TypeError, RuntimeError, OSError):
                return None  # a component is not a group (a dataset's "child")
            if link is None:
                return None
            if isinstance(link, h5py.SoftLink):
                if depth >= _MAX_LINKS:
                    raise self._fail(f"'{name}': more than {_MAX_LINKS} soft links (a loop?)")
                target = link.path if link.path.startswith("/") else f"{done}/{link.path}"
                rest = "/".join(parts[k + 1:])
                resolved = self._link(target, depth + 1)
                return None if resolved is None else (self._link(f"{resolved}/{rest}", depth + 1) if rest else resolved)
            if isinstance(link, h5py.ExternalLink):
                self._external_file(link.filename, f"'{name}' is an external link to {link.filename!r}")
            done = where
        return done or "/"

    def __contains__(self, name: str) -> bool:
        return self._link(name) is not None and name in self.handle

    def keys(self, name: str = "/") -> list[str]:
        """Names in group ``name`` (none when it is missing or not a group)."""
        import h5py

        if name != "/" and (name not in self or self.handle.get(self._resolve(name), getclass=True) is not h5py.Group):
            return []
        return sorted(self.handle[name].keys())

    def _resolve(self, name: str) -> str:
        resolved = self._link(name)
        if resolved is None:
            raise self._fail(f"'{name}': not found")
        return resolved

    # -- datasets ---------------------------------------------------------------------------
    def dataset(self, name: str):
        """The dataset ``name``, its storage checked (see the module docstring)."""
        found = self._open(name)
        if (found.is_virtual or found.external) and not self.allow_external:
            kind = "is a virtual dataset" if found.is_virtual else "has external raw storage"
            raise self._fail(f"'{name}' {kind} (its data is in other files); refused unless {ALLOW}")
        return self.storage_checked(found, name)

    def _open(self, name: str):
        """Dataset ``name`` opened (no data read) so that libhdf5 looks for external and virtual
        source files next to this file, where they are checked (its default for external
        storage is the working folder)."""
        import h5py

        resolved = self._resolve(name)
        kind = self.handle.get(resolved, getclass=True)
        if kind is not h5py.Dataset:
            found = "a group" if kind is h5py.Group else "something else"
            raise self._fail(f"'{name}': expected a dataset, found {found}")
        access = h5py.h5p.create(h5py.h5p.DATASET_ACCESS)
        access.set_efile_prefix(b"${ORIGIN}")
        access.set_virtual_prefix(b"${ORIGIN}")
        return h5py.Dataset(h5py.h5d.open(self.handle.id, resolved.encode(), dapl=access))

    def value(self, name: str, default=None):
        """A (small) dataset's whole value, ``default`` when absent; text decoded."""
        if name not in self:
            return default
        value = self.dataset(name)[()]
        return value.decode("utf-8", "replace") if isinstance(value, bytes) else value

    def storage_checked(self, dataset, name: str):
        """``dataset`` once its storage holds what its shape declares and its filters are available."""
        if dataset.is_virtual:
            self._virtual(dataset, name)
        elif dataset.external:
            self._external_storage(dataset, name)
        else:
            self._allocated(dataset, name)
        return readable(dataset, self.path)

    def _external_file(self, filename: str, what: str) -> int:
        """The size of an external/virtual/linked file, which must be a regular file; found
        relative to this file's folder."""
        if not self.allow_external:
            raise self._fail(f"{what}; refused unless {ALLOW}")
        target = Path(filename) if os.path.isabs(filename) else self.path.parent / filename
        if not lies_in(target, self.path.parent):  # a file from someone else naming ~/.ssh/...
            raise self._fail(f"{what}, outside this file's folder {os.path.realpath(self.path.parent)}; {ALLOW} "
                             "reads only files beside it or below it")
        try:
            with open_regular(target, "file for HDF5 external data") as handle:
                return os.fstat(handle.fileno()).st_size
        except DataError as err:
            raise self._fail(f"{what}: {str(err)[:160]}") from None

    def _external_storage(self, dataset, name: str) -> None:
        needed = dataset.size * dataset.dtype.itemsize
        held = 0
        for filename, offset, size in dataset.external:
            label = filename.decode("utf-8", "replace") if isinstance(filename, bytes) else str(filename)
            available = max(0, self._external_file(label, f"'{name}' keeps its data in {label!r}") - int(offset))
            held += min(available, int(size))
        if held < needed:
            raise self._fail(f"'{name}' declares {needed:,} bytes of external storage, its files hold {held:,}")

    def _virtual(self, dataset, name: str, depth: int = 0) -> None:
        import h5py

        for source in dataset.virtual_sources():
            label = str(source.file_name)
            if label == ".":
                inner = self
            else:
                if "%" in label:  # printf-like patterns name many files: none can be checked
                    raise self._fail(f"'{name}' is a virtual dataset with a file pattern {label!r}; not read")
                self._external_file(label, f"'{name}' is a virtual dataset reading {label!r}")
                target = Path(label) if os.path.isabs(label) else self.path.parent / label
                try:
                    inner = H5File(h5py.File(target, "r"), target, self.allow_external)
                except OSError:
                    raise self._fail(f"'{name}' is a virtual dataset reading {label!r}, not a readable HDF5 "
                                     "file") from None
            try:
                if source.dset_name not in inner:
                    raise self._fail(f"'{name}' is a virtual dataset reading {source.dset_name!r} from "
                                     f"{label!r}, which does not exist there")
                if depth < 2:
                    found = inner._open(source.dset_name)
                    if found.is_virtual:
                        inner._virtual(found, source.dset_name, depth + 1)
                    elif not found.external:
                        inner._allocated(found, source.dset_name)
            finally:
                if inner is not self:
                    inner.handle.close()

    def _allocated(self, dataset, name: str) -> None:
        """Allocated storage covers the declared shape (no fill values read as data)."""
        declared = dataset.size * dataset.dtype.itemsize
        if declared == 0:
            return
        stored = int(dataset.id.get_storage_size())
        filters = dataset.id.get_create_plist().get_nfilters() if dataset.chunks else 0
        problem = None
        if dataset.chunks:
            expected = math.prod(-(-n // c) for n, c in zip(dataset.shape, dataset.chunks))
            written = int(dataset.id.get_num_chunks()) if stored else 0
            if written < expected:
                problem = f"{written:,} of its {expected:,} chunks are written"
            elif filters and declared > max(MAX_INFLATED_BYTES, MAX_INFLATE_RATIO * stored):
                problem = f"{stored:,} compressed bytes would inflate more than {MAX_INFLATE_RATIO}x"
        elif stored < declared:
            problem = f"the file holds {stored:,} bytes of it"
        if problem:
            raise self._fail(f"'{name}' declares shape {dataset.shape} ({declared:,} bytes) but {problem}; "
                             "refused before reading")


def readable(dataset, path: object):
    """``dataset``, after making sure its compression filter can be decoded (``hdf5plugin``)."""
    from h5py import h5z

    plist = dataset.id.get_create_plist()
    for k in range(plist.get_nfilters()):
        code, _, _, name = plist.get_filter(k)
        if code in _BUILTIN_FILTERS or h5z.filter_avail(code):
            continue
        label = name.decode("latin-1", "replace") if isinstance(name, bytes) else str(name)
        require("hdf5plugin", path, f"dataset '{dataset.name}' (compressed with {label or 'filter'} #{code})")
        if not h5z.filter_avail(code):
            raise DataError(located(path, None, f"dataset '{dataset.name}': compression filter #{code} "
                                                f"({label}) is not available even with hdf5plugin"))
    return dataset


__all__ = ["H5File", "readable", "ALLOW"]
