"""Fuzz target ``outputs`` (issue 27): commands whose outputs name their own inputs, hard links
and symlinks to them, and folders tofnet did not write.

A case is a command line (``convert``, ``info``, ``export`` or ``run``) over a small fixture
folder built afresh for each case; words that are not options are names in that folder.
Whatever the command does — write, or refuse with one line — no file it reads and nothing
in a folder of other files may change (same bytes, same inode); a case that changes one
raises ``Invalid`` and is counted as a defect.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
from pathlib import Path

from tofnet.errors import TofnetError, quote

COMMANDS = ("convert", "info", "export", "run")
_QUIET = ["--force", "--quiet"]

#: Valid command lines to mutate: most name an input (or a link to one) as an output.
SEEDS: list[list[str]] = [
    ["convert", "rec", "mine", *_QUIET], ["convert", "rec", "rec", *_QUIET], ["convert", "rec", "sym_rec", *_QUIET],
    ["convert", "rec", "copy", "--quiet"], ["convert", "rec", "events_link.npz", *_QUIET],
    ["convert", "rec/events.txt", "copy.npz", *_QUIET],
    ["info", "rec", "--json", "sym_gt.txt", *_QUIET], ["info", "rec", "--json", "hard_gt.txt", *_QUIET],
    ["info", "rec", "--json", "facts.json", "--quiet"],
    ["export", "d.npz", "--ply", "rec/groundtruth.txt", "--force"], ["export", "d.npz", "--maps", "mine", "--force"],
    ["export", "d.npz", "--maps", "maps_old", "--force"], ["export", "d.npz", "--maps", "sym_rec", "--force"],
    ["export", "d.npz", "--ply", "sym_d.ply", "--force"],
    ["run", "rec", "--spec", "spec.yaml", "--out", "out.npz", "--json", "vel.txt", *_QUIET],
    ["run", "rec", "--velocity", "0.5,0,0", "--out", "sym_calib.csv", *_QUIET],
    ["run", "rec", "--velocity", "0.5,0,0", "--out", "out.csv", "--json", "rec/sensor_size.txt", *_QUIET],
]


def build(folder: Path) -> Path:
    """A fresh fixture: an ECD recording, a depth file naming it, a spec reading velocity
    samples, links to inputs, a folder of other files and an earlier export's maps."""
    import numpy as np

    from tofnet.events import DEPTH_DTYPE, make_events
    from tofnet.io.depth import write_depth
    from tofnet.io.ecd import write_ecd
    from tofnet.io.files import write_manifest
    from tofnet.io.recording import Intrinsics

    root = folder / "outputs-case"
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    write_ecd(root / "rec", make_events([0, 1000, 2000], [1, 2, 3], [1, 1, 1], [1, 1, 1]),
              intrinsics=Intrinsics(200.0, 200.0, 119.5, 89.5), times=[0.0, 1.0], positions=[[0, 0, 0], [0.5, 0, 0]],
              quaternions=[[0, 0, 0, 1], [0, 0, 0, 1]], sensor_size=(240, 180))
    depth = np.zeros(2, dtype=DEPTH_DTYPE)
    depth["t"], depth["x"], depth["z"] = [0, 1000], [1, 2], 1.5
    write_depth(root / "d.npz", depth, t0_us=0, timestep_us=1000, latency_steps=0,
                summary={"recording": str(root / "rec")})
    (root / "vel.txt").write_text("0 0.5 0 0\n1 0.5 0 0\n")
    (root / "spec.yaml").write_text(
        "processes:\n  input: {type: InputProcess, sensor_size: [240, 180]}\n"
        "  time_of_travel: {type: TimeOfTravelProcess}\n  depth: {type: DepthProcess}\n"
        f"  velocity: {{type: VelocityProcess, source: samples, samples: {root / 'vel.txt'}}}\n"
        "connections:\n  - input.events -> time_of_travel.events\n  - time_of_travel.counts -> depth.counts\n"
        "  - velocity.a_t -> depth.a_t\n")
    os.link(root / "rec" / "groundtruth.txt", root / "hard_gt.txt")
    os.link(root / "rec" / "events.txt", root / "events_link.npz")
    for name, target in (("sym_gt.txt", "rec/groundtruth.txt"), ("sym_rec", "rec"), ("sym_d.ply", "d.npz"),
                         ("sym_calib.csv", "rec/calib.txt")):
        (root / name).symlink_to(root / target)
    (root / "mine" / "sub").mkdir(parents=True)
    (root / "mine" / "notes.txt").write_text("not tofnet's")
    (root / "mine" / "sub" / "data.bin").write_bytes(b"\x00\x01")
    (root / "maps_old").mkdir()
    (root / "maps_old" / "index.csv").write_text("window\n")
    write_manifest(root / "maps_old", "tofnet export --maps")
    return root


def _protected(root: Path, args) -> list[Path]:
    """What the command must not change: what it reads, and the folder of other files."""
    names = ["rec", "mine"] + (["d.npz"] if args.command == "export" else [])
    names += ["spec.yaml", "vel.txt"] if getattr(args, "spec", None) else []
    return [p for name in names for p in sorted([root / name, *(root / name).rglob("*")]) if p.exists()]


def _state(paths: list[Path]) -> dict[str, tuple]:
    state = {}
    for path in paths:
        st = os.lstat(path)
        content = path.read_bytes() if path.is_file() and not path.is_symlink() else None
        state[str(path)] = (st.st_ino, content, os.readlink(path) if path.is_symlink() else None)
    return state


def run_case(words: list[str], folder: Path) -> dict:
    """Run one command line over a fresh fixture; the protected files' state, unchanged."""
    from tofnet.cli import build_parser
    from tofnet.fuzzing_checks import Invalid
    from tofnet.io.guard import reading

    if not words or words[0] not in COMMANDS:
        raise TofnetError(f"not a command this target runs: {quote(words[0] if words else '')}")
    root = build(folder)
    argv = [words[0]] + [w if w.startswith("-") or not w else str(root / w) for w in words[1:]]
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            args = build_parser().parse_args(argv)
    except SystemExit:
        raise TofnetError("argparse refused the options (usage and one error line, exit 2)") from None
    protected = _protected(root, args)
    before = _state(protected)
    caller = os.getcwd()
    os.chdir(root)  # a word kept relative (``-1``, ``--force`` taken as a path) lands in the fixture, not the caller's folder
    try:
        with reading(), contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            args.handler(args)
    finally:
        os.chdir(caller)
        after = _state([p for p in protected if os.path.lexists(p)])
        if after != before:
            changed = sorted(set(before) ^ set(after) | {k for k in before if before[k] != after.get(k)})
            raise Invalid(f"{' '.join(words)}: changed {changed[0]} (read by the command or not tofnet's)")
    return after


def check_untouched(result: dict) -> None:
    """``run_case`` compares the protected files itself; nothing more to check."""
