"""``tofnet conformance``: run the conformance cases on backends and print pass/fail per case."""

from __future__ import annotations

import json
import sys

from tofnet.errors import BackendError


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "conformance", help="check that backends compute the same network",
        description="Run the conformance cases (edges, speeds up to counter overflow, textures, noise, borders, "
                    "core boundaries, drops, velocity updates) on a backend and a baseline and compare: exactly "
                    "between integer backends, within the documented tolerances otherwise (docs/backends.md). "
                    "Exits 1 when a case fails.")
    p.add_argument("--backend", action="append", metavar="NAME",
                   help="backend to check (repeatable; default: every registered backend)")
    p.add_argument("--against", default=None, metavar="NAME", help="baseline backend (default: reference)")
    p.add_argument("--case", action="append", metavar="NAME",
                   help="run only this case, or every case starting with it (repeatable)")
    p.add_argument("--workers", metavar="N,N,...",
                   help="instead of a baseline: check that each backend run with N workers (bands of rows) gives "
                        "the bytes it gives with one, fused and model by model, e.g. 1,2,3,7")
    p.add_argument("--list", action="store_true", help="list the cases and the registered backends, run nothing")
    p.add_argument("--json", metavar="FILE", help="also write every case's outcome as JSON")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.backends.registry import available_backends
    from tofnet.conformance import DEFAULT_BASELINE, run_suite, select_cases
    from tofnet.conformance.compare import MODES
    from tofnet.conformance.runner import column_widths, footnote, format_row, header, summary_line
    from tofnet.conformance.workers import check_workers, planned_rows

    cases = select_cases(args.case)
    if args.list:
        width = max(len(c.name) for c in cases)
        for c in cases:
            print(f"{c.name:<{width}}  {c.doc}")
        print()
        for name in available_backends():
            backend, problem = _loaded(name)
            print(f"backend {name:<12} " + (f"arithmetic {backend.arithmetic}" if backend else problem))
        return 0
    if args.json:
        from tofnet.io.files import check_output
        check_output(args.json, force=args.force, what="--json")
    if args.workers and args.against:
        from tofnet.errors import TofnetError
        raise TofnetError("--against and --workers do not go together: --workers checks each backend against "
                          "itself with one worker (run them one after the other)")
    against = args.against or DEFAULT_BASELINE
    backends = args.backend or available_backends()
    workers = workers_list(args.workers) if args.workers else None
    if workers is not None and not args.backend:
        backends = ["fixed", "float"]
    unusable = {name: problem for name in backends for problem in [_loaded(name)[1]] if problem}
    if args.backend and unusable:  # asked for by name: one line before any table
        raise BackendError(next(iter(unusable.values())))
    outcomes, failed, cache = [], 0, {}
    for name in backends:
        if name in unusable:  # a broken plug-in among all the backends: said, counted, and the others still run
            print(f"== {name}: {unusable[name]}\n")
            outcomes.append({"backend": name, "error": unusable[name]})
            continue
        print(f"== {name} with {args.workers} workers vs one" if workers else f"== {name} vs {against}")
        modes = MODES if workers is None else [row[0] for row in planned_rows(_loaded(name)[0], workers)]
        widths = column_widths((c.name for c in cases), modes)  # rows print as they come: every name fits
        print(header(widths))
        report = lambda r: print(format_row(r, widths), flush=True)  # noqa: E731
        if workers is not None:
            results = check_workers(name, workers, [c.name for c in cases], report=report)
        else:
            results = run_suite(name, against, [c.name for c in cases], cache=cache, report=report)
        print(summary_line(results))
        for line in footnote(results):
            print(line)
        print()
        failed += sum(not r.ok for r in results)
        outcomes.extend(r.to_dict() for r in results)
    if args.json:
        from tofnet.io.files import write_text_atomic
        write_text_atomic(args.json, json.dumps(outcomes, indent=2) + "\n")
    if failed:
        print(f"tofnet conformance: {failed} case(s) failed", file=sys.stderr)
    if unusable:
        print(f"tofnet conformance: {len(unusable)} backend(s) could not be loaded: {', '.join(unusable)}",
              file=sys.stderr)
    return 1 if failed or unusable else 0


def _loaded(name: str):
    """``(backend, None)``, or ``(None, why)`` when ``name`` cannot be built (e.g. its plug-in fails to import)."""
    from tofnet.backends.registry import get_backend
    try:
        return get_backend(name), None
    except BackendError as err:
        return None, str(err)


def workers_list(text: str) -> list[int]:
    """``--workers 1,2,3,7``: positive whole numbers."""
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        values = []
    if not values or any(v < 1 for v in values):
        raise BackendError(f"--workers: expected positive whole numbers separated by commas (1,2,3,7), got {text!r}")
    return values
