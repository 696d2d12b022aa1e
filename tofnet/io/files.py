"""Safe file access for every reader and writer of tofnet.

Readers open only regular files (a FIFO, a device such as ``/dev/zero``, a socket or a
folder is refused with one line, never read) and never read more than the file holds.
Writers are atomic: the data goes to a temporary file in the destination folder, is
flushed to disk (``fsync``) and renamed over the final name, so a kill or a full disk
never leaves a partial file under that name; the temporary file is removed on error.
``check_outputs`` validates where outputs go before any work is done. The guarantees
are listed in docs/reliability.md.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import stat
import tempfile
from pathlib import Path
from typing import IO, Iterable, Iterator

from tofnet.errors import DataError, located, quote, reason
from tofnet.io.guard import MANIFEST, foreign_entries, input_among, inputs_under, note_read


def _reason(err: OSError, folder: Path | None = None) -> str:
    """The system's reason; numpy's short writes carry none ("N requested and M written"):
    a full file system under ``folder`` is then named as the reason."""
    if err.strerror:
        return err.strerror
    if folder is not None:
        with contextlib.suppress(OSError):
            if shutil.disk_usage(folder).free < MIN_FREE_BYTES:  # a short write on a (nearly) full disk
                return f"{os.strerror(errno.ENOSPC)} ({reason(err)})"
    return reason(err)


def open_regular(path: str | Path, what: str = "file") -> IO[bytes]:
    """Open ``path`` for binary reading, refusing anything but a regular file.

    The file is opened without blocking (a FIFO with no writer would block ``open``)
    and checked with ``fstat`` on the open descriptor, so a name swapped between the
    check and the read cannot slip through.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except ValueError:  # a NUL byte in the name
        raise DataError(located(path, None, f"not a valid file name for the {what}")) from None
    except FileNotFoundError:
        raise DataError(located(path, None, "file not found")) from None
    except IsADirectoryError:
        raise DataError(located(path, None, f"is a folder, expected a {what}")) from None
    except OSError as err:
        try:  # a socket cannot be opened at all (ENXIO): say what it is
            mode = os.stat(path).st_mode
        except OSError:
            mode = stat.S_IFREG
        if not stat.S_ISREG(mode):
            raise DataError(located(path, None, f"is {_kind(mode)}, expected a regular {what}")) from None
        raise DataError(located(path, None, f"cannot open the {what}: {_reason(err)}")) from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise DataError(located(path, None, f"is {_kind(mode)}, expected a regular {what}"))
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        note_read(path, fd)  # protected from this command's outputs (tofnet.io.guard)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def present(path: str | Path, what: str, *, folder: bool = False) -> bool:
    """Whether an optional file of a recording (a side file, a companion, a calibration) is there.

    ``False`` when nothing has that name; ``True`` for a regular file (a folder with ``folder``).
    Anything else under the name -- a FIFO, a folder, a device, a socket, a symlink to nothing --
    is a one-line ``DataError`` naming the file and what it is (``is a FIFO (named pipe), expected
    {what}``), never taken for missing, as is a name the system cannot look up (permissions, a
    loop of symlinks). A reader opening the file with ``open_regular`` checks it again on the
    descriptor; h5py opens by name, so a file swapped after this check reaches h5py unchecked.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except ValueError:  # a NUL byte: no file can have that name
        return False
    except OSError as err:
        if err.errno not in (errno.ENOENT, errno.ENOTDIR, errno.ENAMETOOLONG):
            raise DataError(located(path, None, f"cannot look up {what}: {_reason(err)}")) from None
        if os.path.islink(path):
            raise DataError(located(path, None, f"is a symbolic link to nothing, expected {what}")) from None
        return False
    if not (stat.S_ISDIR if folder else stat.S_ISREG)(mode):
        raise DataError(located(path, None, f"is {_kind(mode)}, expected {what}"))
    return True


def lies_in(path: str | Path, folder: str | Path) -> bool:
    """Whether ``path`` lies in ``folder`` or below it once links and ``..`` are resolved (False for a name
    the system cannot resolve, one with a NUL say): what a file from someone else may name."""
    try:
        return Path(os.path.realpath(path)).is_relative_to(os.path.realpath(folder))
    except (ValueError, OSError):
        return False


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISREG, "a file"), (stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "not a regular file"


def read_bytes(path: str | Path, what: str = "file", limit: int | None = None) -> bytes:
    """The bytes of a regular file; ``limit`` (bytes) refuses larger files before reading."""
    path = Path(path)
    with open_regular(path, what) as handle:
        size = os.fstat(handle.fileno()).st_size
        if limit is not None and size > limit:
            raise DataError(located(path, None, f"{what} of {size:,} bytes is larger than the limit of "
                                                f"{limit:,} bytes"))
        try:
            data = handle.read(size + 1 if limit is None else limit + 1)
        except OSError as err:
            raise DataError(located(path, None, f"cannot read: {_reason(err)}")) from None
    if limit is not None and len(data) > limit:
        raise DataError(located(path, None, f"{what} is larger than the limit of {limit:,} bytes"))
    return data


def read_text(path: str | Path, what: str = "file", limit: int | None = None) -> str:
    """UTF-8 text of a regular file (see ``read_bytes``); a leading byte-order mark (Windows editors) is dropped."""
    data = read_bytes(path, what, limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise DataError(located(path, None, f"not a text file (byte {err.start} is not UTF-8)")) from None


# ---------------------------------------------------------------- writing

def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb", encoding: str | None = None) -> Iterator[IO]:
    """Write ``path`` atomically: yields a handle on a temporary file in the same folder.

    On success the file is flushed, ``fsync``-ed and renamed to ``path`` (replacing it);
    on any error, including ``KeyboardInterrupt``, the temporary file is removed and
    ``path`` is untouched. Missing parent folders are created. ``OSError`` (read-only
    folder, full disk, ...) becomes a one-line ``DataError`` naming ``path``.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    except OSError as err:
        raise DataError(located(path, None, f"cannot write: {_reason(err)}")) from None
    try:
        with os.fdopen(fd, mode, encoding=encoding) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        refuse_input(path)
        os.replace(tmp, path)
    except BaseException as err:
        why = _reason(err, path.parent) if isinstance(err, OSError) else None  # before the space is freed
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if why is not None:
            raise DataError(located(path, None, f"cannot write: {why}")) from None
        raise
    _sync_folder(path.parent)


def _sync_folder(folder: Path) -> None:
    """Make the rename durable (best effort: not every system can fsync a folder)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | Path, folder: bool = False, written_by: str = "tofnet") -> Iterator[Path]:
    """``atomic_write`` for writers that need a name (h5py, faery) or a whole folder (ECD, maps).

    Yields a temporary path in the destination folder (an empty folder when ``folder``);
    on success the file is ``fsync``-ed and renamed to ``path``, on any error it is
    removed and ``path`` is untouched. A folder gets a manifest (``tofnet.io.guard``,
    ``written_by`` says what wrote it) and replaces an existing folder at ``path`` only
    when that holds nothing but what tofnet wrote there (callers check ``--force`` before).
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if folder:
            tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part"))
        else:
            fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
            os.close(fd)
            tmp = Path(name)
    except OSError as err:
        raise DataError(located(path, None, f"cannot write: {_reason(err)}")) from None
    try:
        yield tmp
        if folder:
            write_manifest(tmp, written_by)
            os.chmod(tmp, 0o777 & ~_umask())
            _replace_folder(tmp, path)
        else:
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.chmod(tmp, 0o666 & ~_umask())
            refuse_input(path)
            os.replace(tmp, path)
    except BaseException as err:
        why = _reason(err, path.parent) if isinstance(err, OSError) else None  # before the space is freed
        with contextlib.suppress(OSError):
            shutil.rmtree(tmp) if tmp.is_dir() else os.unlink(tmp)
        if why is not None:
            raise DataError(located(path, None, f"cannot write: {why}")) from None
        if isinstance(err, DataError) and str(tmp) in str(err):  # name the output, not its temporary copy
            raise DataError(str(err).replace(str(tmp), str(path))) from None
        raise
    _sync_folder(path.parent)


def _replace_folder(tmp: Path, path: Path) -> None:
    """Rename the finished folder ``tmp`` to ``path``; an existing folder there is moved
    aside first and removed after, and only when it holds nothing tofnet did not write."""
    if not (path.is_dir() and not path.is_symlink()):
        refuse_input(path)
        os.replace(tmp, path)
        return
    _refuse_foreign(path, "output")
    held = inputs_under(path)
    if held is not None:
        raise DataError(located(path, None, f"output would replace a folder holding the input {held}; "
                                            "choose another name"))
    old = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".old.part"))
    os.replace(path, old / "previous")
    os.replace(tmp, path)
    shutil.rmtree(old, ignore_errors=True)


def refuse_input(path: str | Path, what: str = "output") -> None:
    """Refuse to replace ``path`` when the command read it (``tofnet.io.guard``)."""
    source = input_among(path)
    if source is not None:
        raise DataError(located(path, None, f"{what} would overwrite the input {source}; choose another name"))


def _refuse_foreign(folder: Path, what: str) -> None:
    foreign = foreign_entries(folder)
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise DataError(located(folder, None, f"{what} is a folder holding {quote(foreign[0])}{more}, which tofnet "
                                              f"did not write (not in its {MANIFEST}); tofnet replaces only "
                                              "an empty folder or one it wrote: choose another name"))


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    with atomic_write(path, "w", encoding="utf-8") as handle:
        handle.write(text)


def write_manifest(folder: str | Path, written_by: str, files: Iterable[str] | None = None) -> None:
    """Mark ``folder`` as tofnet's (``tofnet.io.guard.MANIFEST``): ``files`` are relative
    names (default: every file in it now)."""
    folder = Path(folder)
    if files is None:
        files = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.name != MANIFEST and p.is_file())
    write_text_atomic(folder / MANIFEST, json.dumps({"written_by": written_by, "files": list(files)}, indent=1) + "\n")


# ---------------------------------------------------------------- checking outputs before the work

def check_output(path: str | Path, *, force: bool = False, inputs: Iterable[str | Path] = (),
                 what: str = "output", option: str = "--force", folder: bool = False) -> Path:
    """Check that ``path`` can be written, before any work is done; returns it.

    Refused: a path that is a folder, one under a file, one whose nearest existing
    folder is not writable or has no free space, an input file (listed in ``inputs`` or
    read so far by the command, ``tofnet.io.guard``; same path or inode; even with
    ``force``), and an existing file unless ``force``. With ``folder`` the output is a
    whole folder (an ECD recording, depth maps): an existing folder that is not empty is
    replaced only with ``force``, only when it holds nothing but what tofnet wrote there
    (its manifest), and never when it holds an input.
    """
    path = Path(path)
    if path.name in ("", ".", "..") or "\x00" in str(path):
        raise DataError(located(path, None, f"{what}: expected a {'folder' if folder else 'file'} name"))
    try:
        return _check_output(path, force, list(inputs), what, option, folder)
    except OSError as err:  # a name too long, a loop of symlinks, ...: the system's reason, one line
        raise DataError(located(path, None, f"{what}: {_reason(err)}")) from None


def _check_output(path: Path, force: bool, inputs: list, what: str, option: str, folder: bool) -> Path:
    source = input_among(path, inputs) if path.exists() or path.is_symlink() else None
    if source is not None:
        raise DataError(located(path, None, f"{what} would overwrite the input {source}; choose another name"))
    if folder:
        held = inputs_under(path, inputs) if path.is_dir() and not path.is_symlink() else None
        if held is not None:
            raise DataError(located(path, None, f"{what} would replace a folder holding the input {held}; "
                                                "choose another name"))
    if path.is_dir() and not folder:
        raise DataError(located(path, None, f"{what} is a folder, expected a file name"))
    if path.exists() or path.is_symlink():
        wrong_kind = (not path.is_dir() or path.is_symlink()) if folder else not path.is_file()
        if wrong_kind:
            if folder and path.is_symlink():  # replacing it would write beside a folder elsewhere: never
                raise DataError(located(path, None, f"{what} is a symbolic link; a folder output is written under "
                                                    "a real folder's name: name the folder itself"))
            kind = "folder" if folder else "regular file"
            raise DataError(located(path, None, f"{what} exists and is not a {kind}"))
        if folder:
            _refuse_foreign(path, what)
        if not force and not (folder and not any(path.iterdir())):
            raise DataError(located(path, None, f"{what} exists; pass {option} to overwrite it"))
    check_folder_writable(path.parent, what)
    return path


def check_folder_writable(folder: str | Path, what: str = "output") -> None:
    """The nearest existing ancestor of ``folder`` must be a writable folder."""
    folder = Path(folder) if str(folder) else Path(".")
    probe = nearest_existing(folder)
    if not probe.is_dir():
        raise DataError(located(folder, None, f"{what}: cannot create a folder under {probe}, which is a file"))
    if not os.access(probe, os.W_OK | os.X_OK):
        raise DataError(located(probe, None, f"{what}: the folder is not writable"))
    # Permission bits do not show a read-only mount (nor root's limits): try a file.
    try:
        fd, tmp = tempfile.mkstemp(dir=probe, prefix=".tofnet-probe.", suffix=".part")
        os.close(fd)
        os.unlink(tmp)
    except OSError as err:
        raise DataError(located(probe, None, f"{what}: cannot write in this folder: {_reason(err)}")) from None
    check_free_space(probe, what)


#: Bytes a file system must have free for an output to be started (a full one is refused
#: before the work, not when the first block is written).
MIN_FREE_BYTES = 1 << 20


def nearest_existing(path: str | Path) -> Path:
    """``path``, or its nearest ancestor that exists (where a new output would be made)."""
    probe = Path(path) if str(path) else Path(".")
    while not (probe.exists() or probe.is_symlink()) and probe.parent != probe:
        probe = probe.parent
    return probe


def free_bytes(path: str | Path) -> int | None:
    """Bytes free on the file system ``path`` (or the nearest existing ancestor) would be written to; None
    when it does not say."""
    try:
        return shutil.disk_usage(nearest_existing(path)).free
    except OSError:
        return None


def check_free_space(folder: str | Path, what: str = "output", needed: int = MIN_FREE_BYTES) -> None:
    """Refuse a folder on a file system with less than ``needed`` bytes free (when it says)."""
    free = free_bytes(folder)
    if free is not None and free < needed:
        raise DataError(located(folder, None, f"{what}: the file system is full ({free:,} bytes free, "
                                              f"at least {needed:,} needed)"))


def distinct_outputs(paths: dict[str, str | Path | None]) -> None:
    """Refuse two outputs (``{option: path}``) naming the same file."""
    seen: dict[Path, str] = {}
    for option, path in paths.items():
        if path is None:
            continue
        if "\x00" in str(path):
            raise DataError(located(path, None, f"{option}: expected a file name"))
        key = Path(path).resolve()
        if key in seen:
            raise DataError(f"{option} and {seen[key]} name the same file {path}; choose two names")
        seen[key] = option
