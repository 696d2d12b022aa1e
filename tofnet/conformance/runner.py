"""Running the conformance cases on a backend and a baseline, and the table of outcomes."""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from typing import Callable, Iterable

from tofnet.backends.base import Backend
from tofnet.backends.registry import get_backend
from tofnet.conformance.cases import CASES, Case, get_case
from tofnet.conformance.compare import compare, mode_of
from tofnet.conformance.variables import compare_variables
from tofnet.core.ports import OutPort
from tofnet.errors import BackendError, TofnetError, UnsupportedError

DEFAULT_BASELINE = "reference"


@dataclass
class CaseResult:
    """One case on one backend: ``ok``, the comparison mode, estimate counts
    (backend, baseline) and the first difference (or error) when it failed. ``applies`` is
    False (and ``ok`` True) when the backend cannot hold a process of the case's network
    (``UnsupportedError``; ``first`` says why)."""

    case: str
    backend: str
    baseline: str
    mode: str
    ok: bool
    estimates: tuple[int, int]
    first: str
    seconds: float
    applies: bool = True

    def to_dict(self) -> dict:
        return dict(self.__dict__, estimates=list(self.estimates))


class BackendRunner:
    """Runs compiled networks on one backend, through a session when the backend offers one
    (the multiproc backend then spawns its workers once for the whole suite)."""

    def __init__(self, backend: Backend, stack: contextlib.ExitStack):
        self.backend, self.stack = backend, stack
        self.session = None

    @property
    def arithmetic(self) -> str:
        return self.backend.arithmetic

    def session_or_backend(self):
        """What a ``Session`` should run on: the open multiproc session (its workers), else the backend."""
        if "workers" in self.backend.capabilities:
            if self.session is None:
                self.session = self.stack.enter_context(self.backend.session())
            return self.session
        return self.backend

    def run(self, compiled, recording, *, record_tot: bool = True, probes=()):
        if "workers" not in self.backend.capabilities:
            return self.backend.run(compiled, recording, record_tot=record_tot, probes=probes)
        if self.session is None:
            self.session = self.stack.enter_context(self.backend.session())
        try:
            return self.session.run(recording, compiled=compiled, record_tot=record_tot, probes=probes)
        except Exception:
            self.session = None  # a failed session is closed; the next case opens a new one
            raise


def _backend(spec: str | Backend) -> Backend:
    return get_backend(spec) if isinstance(spec, str) else spec


def select_cases(names: Iterable[str] | None = None) -> list[Case]:
    """The cases called ``names`` (all when None); prefix matches allowed (``speed-`` = every speed)."""
    if names is None:
        return list(CASES)
    chosen = []
    for name in names:
        matches = [c for c in CASES if c.name == name] or [c for c in CASES if c.name.startswith(name)]
        if not matches:
            raise BackendError(f"unknown conformance case {name!r}; 'tofnet conformance --list' shows them")
        chosen.extend(c for c in matches if c not in chosen)
    return chosen


def run_suite(backend: str | Backend, against: str | Backend = DEFAULT_BASELINE,
              cases: Iterable[str] | None = None, *, cache: dict | None = None,
              report: Callable[[CaseResult], None] | None = None) -> list[CaseResult]:
    """Run every selected case on ``backend`` and on the baseline ``against`` and compare.

    ``cache`` (a dict) keeps baseline results between calls, keyed by baseline and case
    name; ``report`` is called with each case's result as soon as it is known.
    """
    from tofnet.compiler import compile_network

    test, base = _backend(backend), _backend(against)
    mode = mode_of(test.arithmetic, base.arithmetic)
    results = []
    with contextlib.ExitStack() as stack:
        runners = {"test": BackendRunner(test, stack), "base": BackendRunner(base, stack)}
        for case in select_cases(cases):
            started = time.perf_counter()
            try:
                scene = case.build()
                compiled = compile_network(scene.network, patch=scene.patch)
                key = (base.name, case.name)
                probes = rotation_probes(compiled.network)
                if cache is not None and key in cache:
                    expected = cache[key]
                else:
                    expected = runners["base"].run(compiled, scene.recording, probes=probes)
                    if cache is not None:
                        cache[key] = expected
                got = runners["test"].run(compiled, scene.recording, probes=probes)
                comparison = compare(got, expected, mode, compiled.network, scene.recording)
                if case.variables_at:
                    comparison.differences += compare_variables(compiled, scene.recording, runners["test"],
                                                                runners["base"], case.variables_at)
                outcome = CaseResult(case.name, test.name, base.name, mode, comparison.ok, comparison.estimates,
                                     comparison.first, time.perf_counter() - started)
            except UnsupportedError as err:
                outcome = CaseResult(case.name, test.name, base.name, mode, True, (0, 0), f"n/a: {err}",
                                     time.perf_counter() - started, applies=False)
            except Exception as err:  # a backend's bug is a failed case, not the end of the suite
                what = str(err) if isinstance(err, TofnetError) else f"{type(err).__name__}: {err}"
                outcome = CaseResult(case.name, test.name, base.name, mode, False, (0, 0),
                                     f"error: {what}", time.perf_counter() - started)
            results.append(outcome)
            if report is not None:
                report(outcome)
    return results


def rotation_probes(network) -> list[str]:
    """The angular velocity updates a depth process's eq. 7 bound reads (``compare``): every
    connected ``rotation_term`` output. (Probing nothing else keeps the paper's chain fused.)"""
    return [port.qualified_name for p in network.processes for port in p.ports.values()
            if isinstance(port, OutPort) and port.spec.payload.name == "rotation_term" and port.targets]


#: Why a row may pass with unequal estimate counts, by comparison mode (``compare``'s rules).
UNEQUAL_PASSES = {
    "quantised": "fixed vs float: an estimate may be on one side only when its depth lies within the quantisation "
                 "tolerance (|m_x| + |m_y|) * 2^-(F+1) of min_depth or max_depth (eq. 7: its share within it of "
                 "min_share), and the rejection counts must differ by exactly those estimates "
                 "(docs/fixed_point.md, tolerance between the fixed and the float backends)",
}


def unequal(r: CaseResult) -> bool:
    """A passing row whose backends gave different numbers of estimates (within its mode's tolerance)."""
    return r.applies and r.ok and r.estimates[0] != r.estimates[1]


def footnote(results: list[CaseResult]) -> list[str]:
    """The lines that say why the ``pass*`` rows (unequal estimate counts) pass; none without such rows."""
    modes = dict.fromkeys(r.mode for r in results if unequal(r))
    return [f"pass* ({mode}): {UNEQUAL_PASSES.get(mode, 'within the tolerance docs/backends.md states')}"
            for mode in modes]


#: The narrowest case and mode columns of the table.
COLUMNS = (24, 10)


def column_widths(cases: Iterable[str], modes: Iterable[str]) -> tuple[int, int]:
    """The widths of the case and mode columns that hold every name given (at least ``COLUMNS``)."""
    return max([COLUMNS[0], *map(len, cases)]), max([COLUMNS[1], *map(len, modes)])


def format_row(r: CaseResult, widths: tuple[int, int] = COLUMNS) -> str:
    estimates = f"{r.estimates[0]}/{r.estimates[1]}"
    first = r.first.splitlines()[0] if r.first else ""
    verdict = "n/a" if not r.applies else ("pass*" if unequal(r) else "pass") if r.ok else "FAIL"
    return f"{r.case:<{widths[0]}} {r.mode:<{widths[1]}} {verdict:<5} {estimates:>11}  {first}"


def header(widths: tuple[int, int] = COLUMNS) -> str:
    return f"{'case':<{widths[0]}} {'mode':<{widths[1]}} {'':<5} {'estimates':>11}  first difference"


def format_table(results: list[CaseResult]) -> str:
    """The table of cases (pass/fail, estimates backend/baseline, first difference) and a total line."""
    widths = column_widths((r.case for r in results), (r.mode for r in results))
    lines = [header(widths)] + [format_row(r, widths) for r in results] + [summary_line(results)] + footnote(results)
    return "\n".join(lines)


def summary_line(results: list[CaseResult]) -> str:
    failed = sum(not r.ok for r in results)
    skipped = sum(not r.applies for r in results)
    pair = f"{results[0].backend} vs {results[0].baseline}" if results else ""
    seconds = sum(r.seconds for r in results)
    apart = f", {skipped} not applicable" if skipped else ""
    return (f"{len(results)} cases: {len(results) - failed - skipped} passed{apart}, {failed} failed "
            f"({pair}, {seconds:.1f} s)")


__all__ = ["CaseResult", "run_suite", "format_table", "format_row", "footnote", "header", "summary_line",
           "column_widths", "select_cases", "get_case", "DEFAULT_BASELINE"]
