"""Where a batch writes, checked before any task runs, and what a task's inputs are.

A batch's output folder follows the rule of every tofnet output
(``tofnet.io.files.check_output``): it is new, empty, or an earlier batch's (marked by
its manifest, ``tofnet.io.guard``) and then needs ``--force`` or ``--resume``; it never
holds files tofnet did not write there, nor an input of the plan (the plan, its specs,
its recordings and their side files, calibration files). Resume compares a content
fingerprint of a task's inputs, not their paths alone.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from tofnet.batch.plan import Plan
from tofnet.batch.tasks import SCENARIO_FILE, TASKS_DIR, Task

#: What a batch writes at the top of its output folder (besides the scenario cache).
BATCH_FILES = ("results.csv", "results.parquet", "plot.png", TASKS_DIR)
#: Bytes hashed at the start, middle and end of each input file for a sampled fingerprint.
SAMPLE_BYTES = 1 << 16
FINGERPRINTS = ("sample", "full")


def plan_inputs(plan: Plan) -> list[Path]:
    """Every file the plan's tasks read that exists before the batch: the plan, the specs,
    the recordings with their side files, and files named by reading keys (``calib``)."""
    from tofnet.io.ecd import recording_files

    inputs = [Path(plan.source)] if plan.source != "<string>" else []
    inputs += [Path(network.spec) for network in plan.networks if network.spec]
    for recording in plan.recordings:
        if recording.path is not None:
            inputs += [Path(recording.path), *recording_files(recording.path)]
        inputs += [Path(value) for value in recording.options.values() if _names_file(value)]
    return inputs


def _names_file(value) -> bool:
    return isinstance(value, (str, Path)) and "\x00" not in str(value) and Path(value).is_file()


def check_batch_output(plan: Plan, *, force: bool = False, resume: bool = False) -> None:
    """Refuse, before any task runs, an output folder the batch must not or cannot write
    (and a scenario cache that cannot be written); one line naming the folder."""
    from tofnet.io.files import check_folder_writable, check_output

    check_output(plan.output, force=force or resume, inputs=plan_inputs(plan), what="output", folder=True,
                 option="--resume to continue it, or --force")
    check_folder_writable(plan.output, "output")
    if any(recording.scenario is not None for recording in plan.recordings):
        check_cache(plan.cache)
        check_folder_writable(plan.cache, "cache")


#: What a desktop's file browser leaves in any folder it showed (macOS, Windows): not the user's data.
_DESKTOP_FILES = {".DS_Store", "Thumbs.db", "desktop.ini"}


def check_cache(cache: Path) -> None:
    """Refuse a scenario cache that holds anything but scenario folders (each with its ``scenario.json``)
    and their temporary folders: a plan from someone else naming a folder of yours (``cache: ~/data``)
    would fill it with simulations. One line naming the folder and the first entry that is not tofnet's."""
    from tofnet.errors import DataError, located, quote
    if not cache.is_dir():
        return
    foreign = [entry.name for entry in sorted(cache.iterdir()) if entry.name not in _DESKTOP_FILES and (
               entry.is_symlink() or not entry.is_dir()
               or not ((entry / SCENARIO_FILE).is_file() or (entry.name.startswith(".") and ".tmp-" in entry.name)))]
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise DataError(located(cache, None, f"cache is a folder holding {quote(foreign[0])}{more}, which is not a "
                                             "simulated scenario; a scenario cache holds only tofnet's scenario "
                                             "folders: name an empty or new folder, or one an earlier batch filled"))


def mark_output(plan: Plan) -> None:
    """Create the output folder and its manifest (before any task writes there)."""
    from tofnet.io.files import write_manifest

    names = list(BATCH_FILES)
    cache = plan.cache.resolve()
    if cache.parent == plan.output.resolve():
        names.append(cache.name)
    plan.output.mkdir(parents=True, exist_ok=True)
    write_manifest(plan.output, "tofnet batch", names)


def fingerprint(task: Task, how: str = "sample", memo: dict | None = None) -> str | None:
    """A content fingerprint of ``task``'s input files (``None`` for a simulated scenario,
    whose cache key already says what it holds): per file its size, ``mtime`` and a hash of
    three samples of its content (``how="sample"``) or of all of it (``"full"``)."""
    if task.recording.path is None:
        return None
    from tofnet.io.ecd import recording_files

    files = [Path(task.recording.path), *recording_files(task.recording.path)]
    files += [Path(v) for v in task.recording.options.values() if _names_file(v)]
    if task.network.spec:
        files.append(Path(task.network.spec))
    h = hashlib.sha256(how.encode())
    for path in sorted({str(p) for p in files if p.is_file()}):
        digest = memo.get(path) if memo is not None else None
        if digest is None:
            digest = _file_digest(Path(path), how)
            if memo is not None:
                memo[path] = digest
        h.update(digest.encode())
    return h.hexdigest()[:20]


def _file_digest(path: Path, how: str) -> str:
    st = os.stat(path)
    h = hashlib.sha256(f"{path}:{st.st_size}:{st.st_mtime_ns}".encode())
    with open(path, "rb") as handle:
        if how == "full" or st.st_size <= 3 * SAMPLE_BYTES:
            for block in iter(lambda: handle.read(1 << 20), b""):
                h.update(block)
        else:
            for offset in (0, (st.st_size - SAMPLE_BYTES) // 2, st.st_size - SAMPLE_BYTES):
                handle.seek(offset)
                h.update(handle.read(SAMPLE_BYTES))
    return h.hexdigest()
