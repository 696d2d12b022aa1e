"""Output checks the subcommands run before any work (the logic is ``tofnet.io.files``)."""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import TofnetError, quote


def check_run_outputs(args) -> None:
    """``tofnet run``: refuse, before reading anything, outputs that cannot or must not be
    written (``--out``, ``--json``, the ``--record-tot`` file); the run would otherwise
    fail only at its end. See ``tofnet.io.files.check_output``."""
    from tofnet.io.ecd import recording_files
    from tofnet.io.files import check_output, distinct_outputs

    out = Path(args.out)
    outputs = {"--out": out, "--json": args.json,
               "the --record-tot file": out.with_name(out.stem + "_tot.npz") if args.record_tot else None}
    distinct_outputs(outputs)
    inputs = recording_files(args.recording) + ([Path(args.spec)] if args.spec else [])
    for option, path in outputs.items():
        if path is not None:
            check_output(path, force=args.force, inputs=inputs, what=option)
    if out.suffix not in (".npz", ".csv"):
        raise TofnetError(f"--out: depth output must be a .npz or .csv file, got {quote(out.name)}")
