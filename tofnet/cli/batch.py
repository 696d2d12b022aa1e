"""``tofnet batch``: run a plan of recordings x networks x parameters on Dask (docs/batch.md)."""

from __future__ import annotations

import sys
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser("batch", help="run a plan of recordings x networks x parameters on Dask",
                              description="Run every (recording, network, parameters) task of a YAML plan on a "
                                          "Dask cluster (a local one by default) and write one table of results "
                                          "(results.csv, and results.parquet with pyarrow) and plot.png. "
                                          "Needs the batch extra: pip install \"tofnet[batch]\".")
    p.add_argument("plan", help="YAML plan (see docs/batch.md)")
    p.add_argument("-o", "--out", metavar="DIR",
                   help="output folder (default: the plan's output:, else NAME-results/ beside the plan, NAME the "
                        "plan's name: or its file name)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="use an existing Dask scheduler, e.g. tcp://host:8786 "
                                                          "(default: start a local cluster)")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: one per core)")
    p.add_argument("--memory-limit", default="auto", metavar="SIZE",
                   help="memory per local worker, e.g. 2GB (default: auto, the machine's memory shared equally)")
    p.add_argument("--resume", action="store_true", help="skip the tasks whose outputs are already complete "
                                                         "(and whose input files are unchanged)")
    p.add_argument("--force", action="store_true", help="run every task again into an earlier batch's output "
                                                        "folder (never a folder of other files, never an input)")
    p.add_argument("--fingerprint", choices=("sample", "full"), default="sample",
                   help="how --resume tells an input changed: size, mtime and a hash of three 64 KiB samples "
                        "(default), or a hash of whole files")
    p.add_argument("--check", action="store_true", help="validate the plan and list its tasks; run nothing")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    from tofnet.cli.trust import add_allow_import
    add_allow_import(p)
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.batch import expand, load_plan, require_dask
    from tofnet.errors import TofnetError

    if args.workers is not None and args.workers < 1:
        raise TofnetError(f"--workers: expected at least 1, got {args.workers}")
    if args.scheduler and args.workers:
        raise TofnetError("--workers applies to the local cluster; with --scheduler the cluster has its own workers")
    if not args.check:
        require_dask()
    plan = load_plan(Path(args.plan), output=args.out, allow_import=args.allow_import)
    tasks = expand(plan)
    if args.check:
        print(f"plan {plan.name}: {len(plan.recordings)} recordings x {len(plan.networks)} networks x "
              f"{len(plan.combinations())} grid points = {len(tasks)} tasks -> {plan.output}")
        if any(recording.scenario is not None for recording in plan.recordings):
            print(f"scenarios simulated into {plan.cache}")
        for task in tasks:
            print(f"  {task.number:4d}  {task.task_id}")
        return 0
    from tofnet.batch.runner import Progress, run_batch
    try:
        result = run_batch(plan, scheduler=args.scheduler, workers=args.workers,
                           memory_limit=_memory(args.memory_limit), resume=args.resume, force=args.force,
                           fingerprints=args.fingerprint,
                           progress=None if args.quiet else Progress())
    except KeyboardInterrupt:
        print(f"tofnet batch: interrupted; finished tasks are kept in {plan.output}; "
              f"run again with --resume for the rest", file=sys.stderr)
        return 130
    print(format_result(result))
    return 1 if result.failed else 0


def format_result(result) -> str:
    """The closing report: counts, failures (one line each), and the files written."""
    rows = result.rows
    ok = len(rows) - len(result.failed)
    events = sum(r.get("events_in") or 0 for r in rows if r.get("status") == "ok")
    lines = [f"batch {result.plan.name}: {len(rows)} tasks, {ok} ok, {len(result.failed)} failed"
             f"{f', {result.resumed} already complete (--resume)' if result.resumed else ''}; "
             f"{events:,} events in {result.wall_time_s:.1f} s"
             f"{f' on {result.workers} worker' + ('s' if result.workers != 1 else '') if result.workers else ''}"]
    for row in result.failed[:20]:
        lines.append(f"  failed  {row['task_id']}: {row.get('error')}")
    if len(result.failed) > 20:
        lines.append(f"  ... and {len(result.failed) - 20} more (see the status and error columns)")
    lines.append("table   " + ", ".join(str(f) for f in result.files))
    if result.plot is not None:
        lines.append(f"plot    {result.plot}")
    return "\n".join(lines)


def _memory(value: str):
    """``auto``, a byte count, or a size text like ``2GB`` (Dask parses it)."""
    return int(value) if value.isdigit() else value


if __name__ == "__main__":  # pragma: no cover
    from tofnet.cli import main
    sys.exit(main(["batch", *sys.argv[1:]]))
