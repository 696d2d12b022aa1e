"""Output checks the subcommands run before any work (the logic is ``tofnet.io.files``)."""

from __future__ import annotations

from pathlib import Path

from tofnet.errors import TofnetError, quote


def check_run_outputs(args, network=None) -> None:
    """``tofnet run``: refuse, before reading anything, outputs that cannot or must not be
    written (``--out``, ``--json``, the ``--record-tot`` and ``--probe`` files); the run would otherwise
    fail only at its end. Run again once the ``network`` is built: the files its processes
    will read, and the files read so far, are inputs too. See ``tofnet.io.files.check_output``."""
    from tofnet.io.files import check_output, distinct_outputs

    out = Path(args.out)
    outputs = _early_outputs(args)
    distinct_outputs(outputs)
    inputs = _run_inputs(args) + (network_files(network) if network is not None else [])
    for option, path in outputs.items():
        if path is not None:
            check_output(path, force=args.force, inputs=inputs, what=option)
    if out.suffix.lower() not in (".npz", ".csv"):
        raise TofnetError(f"--out: depth output must be a .npz or .csv file, got {quote(out.name)}")


def _run_inputs(args) -> list[Path]:
    from tofnet.io.ecd import recording_files

    return recording_files(args.recording) + ([Path(args.spec)] if args.spec else [])


def network_files(network) -> list[Path]:
    """The files the processes of ``network`` will read (parameters declared ``reads_file``)."""
    files = []
    for process in network.processes:
        for param in process.params:
            value = process.values.get(param.name) if param.reads_file else None
            if value is not None:
                files.append(Path(value))
    return files


def _early_outputs(args) -> dict[str, Path | None]:
    out = Path(args.out)
    outputs = {"--out": out, "--json": Path(args.json) if args.json else None,
               "the --record-tot file": out.with_name(out.stem + "_tot.npz") if args.record_tot else None}
    for probe in getattr(args, "probe", None) or []:
        outputs[f"--probe {quote(probe, 30)}"] = out.with_name(f"{out.stem}.{probe}.npz")
    return outputs


def check_more_outputs(args, paths: list[Path]) -> None:
    """``tofnet run``: the files named only once the network is known (one per depth output
    of a network with several), checked like the others before any is written."""
    from tofnet.io.files import check_output, distinct_outputs

    early = _early_outputs(args)
    # the summary is written apart from these files: a file of the run named as --json would hold the summary
    distinct_outputs({"--json": early["--json"], **{f"the output {path}": Path(path) for path in paths}})
    checked = {path.resolve() for path in early.values() if path is not None}
    inputs = _run_inputs(args)
    for path in paths:
        if Path(path).resolve() not in checked:
            check_output(path, force=args.force, inputs=inputs, what="output")
