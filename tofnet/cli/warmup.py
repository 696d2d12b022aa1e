"""``tofnet warmup``: compile every kernel ahead (numba caches them on disk), so no later run waits for it."""

from __future__ import annotations

import time


def register(subparsers) -> None:
    from tofnet.warmup import WARMERS

    p = subparsers.add_parser("warmup", help="compile every kernel ahead (once per install; later runs start at once)",
                              description="Compile the numba kernels of every backend family and of the simulator "
                                          "(1-3 min on a fresh install on 2 cores; numba caches them, so this runs once). Runs "
                                          "compile what they need themselves; this only moves the wait ahead.")
    p.add_argument("only", nargs="*", metavar="WARMER", help=f"warm only these ({', '.join(WARMERS)}; default: all)")
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.kernels.compilation import announce_compiling, kernels
    from tofnet.warmup import check_names, warm_up

    names = check_names(args.only or None)  # before saying anything
    started = time.perf_counter()
    announce_compiling(False)  # a run's "compiling kernels (20-60 s)" line: this says its own wait
    print("warming up every kernel tofnet runs (1-3 min on a fresh install on 2 cores, once: numba caches them) ...",
          flush=True)
    done = warm_up(names, report=lambda warmed: print(warmed.line(), flush=True))
    compiled = sum(w.compiled for w in done)
    print(f"done in {time.perf_counter() - started:.1f} s: {kernels(compiled)} compiled"
          + ("" if compiled else " (all were already in numba's cache)"))
    return 0
