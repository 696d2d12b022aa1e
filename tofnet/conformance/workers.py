"""Workers change nothing: every case run with N bands equals the same backend with one, byte for byte.

``check_workers("fixed", (1, 2, 3, 7))`` runs each selected case on the backend with one worker
and with each N of ``workers`` (the sensor cut into N bands, ``tofnet.backends.bands``), in each
way the backend offers to run a network (``Backend.run_modes``: fused and model by model; for
``multiproc`` bands and chip core by chip core), and compares every output's bytes, every count, the steps,
``t0`` and what a user reads (payloads, declared counts, the summary: ``visible.py``)
(``tofnet conformance --backend fixed --workers 1,2,3,7``). Small scenes cut into 7
bands have bands narrower than the halo, bands without events and events on band edges.
"""

from __future__ import annotations

import time
from typing import Callable, Iterable

from tofnet.backends.base import Backend
from tofnet.backends.registry import get_backend
from tofnet.conformance.visible import visible_differences
from tofnet.conformance.runner import CaseResult, select_cases
from tofnet.errors import TofnetError

#: The band counts the suite checks by default.
DEFAULT_WORKERS = (1, 2, 3, 7)


def first_difference(got, expected) -> str:
    """The first way two results differ (steps, t0, counts, outputs by bytes, then what a user reads:
    payloads, declared counts, the summary), or '' when identical."""
    for what in ("steps", "t0_us", "counts"):
        if getattr(got, what) != getattr(expected, what):
            return f"{what}: {getattr(got, what)!r} vs {getattr(expected, what)!r}"
    if set(got.outputs) != set(expected.outputs):
        return f"outputs {sorted(got.outputs)} vs {sorted(expected.outputs)}"
    for name in sorted(got.outputs):
        a, b = got.outputs[name], expected.outputs[name]
        if a.dtype != b.dtype or a.tobytes() != b.tobytes():
            at = next((i for i in range(min(len(a), len(b))) if a[i].tobytes() != b[i].tobytes()), min(len(a), len(b)))
            return f"{name}: {len(a)} vs {len(b)} records, first differing at {at}"
    return next(iter(visible_differences(got, expected)), "")


def planned_rows(backend: Backend, workers: Iterable[int], modes: Iterable[str] | None = None
                 ) -> list[tuple[str, str, int, dict]]:
    """The rows ``check_workers`` gives each case: ``(row mode, run mode, N, the backend's options)``, the
    row mode ``bands-N`` for the first of the backend's ``run_modes``, ``bands-N-<mode>`` for the others;
    one n/a row ``bands`` for a backend whose capabilities have no ``"bands"`` (it takes no ``workers``)."""
    if "bands" not in backend.capabilities:
        return [("bands", "", 0, {})]
    offered = backend.run_modes
    chosen = [m for m in offered if modes is None or m[0] in set(modes)]
    return [(f"bands-{n}" + ("" if name == offered[0][0] else f"-{name}"), name, n, options)
            for name, options in chosen for n in workers]


def check_workers(backend: str = "fixed", workers: Iterable[int] = DEFAULT_WORKERS,
                  cases: Iterable[str] | None = None, *, modes: Iterable[str] | None = None,
                  report: Callable[[CaseResult], None] | None = None) -> list[CaseResult]:
    """Each case on ``backend`` with each N of ``workers`` against one worker, in each of the backend's
    ``run_modes`` (all by default; ``planned_rows`` names them); one ``CaseResult`` per case, N and mode.
    A backend that takes no ``workers`` (no ``"bands"`` in its capabilities) is n/a, one row per case."""
    from tofnet.compiler import compile_network

    built = get_backend(backend)
    rows = planned_rows(built, list(workers), modes)
    results = []
    for case in select_cases(cases):
        if "bands" not in built.capabilities:
            why = f"n/a: backend {backend!r} takes no workers (Backend.capabilities has no 'bands')"
            results.append(CaseResult(case.name, backend, backend, "bands", True, (0, 0), why, 0.0, applies=False))
            if report is not None:
                report(results[-1])
            continue
        scene = case.build()
        compiled = compile_network(scene.network, patch=scene.patch)
        baselines: dict[str, object] = {}
        for mode, run_mode, n, options in rows:
            started = time.perf_counter()
            try:
                if run_mode not in baselines:
                    baselines[run_mode] = get_backend(backend, workers=1, **options).run(compiled, scene.recording,
                                                                                         record_tot=True)
                baseline = baselines[run_mode]
                got = get_backend(backend, workers=n, **options).run(compiled, scene.recording, record_tot=True)
                first = first_difference(got, baseline)
                estimates = tuple(sum(len(r.outputs[name]) for name in r.depth_outputs) for r in (got, baseline))
            except Exception as err:  # a backend's bug is a failed case, not the end of the suite
                first = "error: " + (str(err) if isinstance(err, TofnetError) else f"{type(err).__name__}: {err}")
                estimates = (0, 0)
            outcome = CaseResult(case.name, f"{backend} x{n}", f"{backend} x1", mode, not first, estimates,
                                 first, time.perf_counter() - started)
            results.append(outcome)
            if report is not None:
                report(outcome)
    return results
