"""The conformance suite: named cases run on a backend and a baseline, compared exactly or
within the stated tolerances (docs/backends.md). From Python::

    from tofnet.conformance import run_suite, format_table
    print(format_table(run_suite("multiproc", against="fixed")))

or ``tofnet conformance --backend multiproc --against fixed``.
"""

from tofnet.conformance.cases import CASES, Case, Scene, get_case
from tofnet.conformance.compare import Comparison, compare, mode_of
from tofnet.conformance.runner import DEFAULT_BASELINE, BackendRunner, CaseResult, format_table, run_suite, select_cases

__all__ = ["CASES", "Case", "Scene", "get_case", "Comparison", "compare", "mode_of", "DEFAULT_BASELINE", "BackendRunner",
           "CaseResult", "format_table", "run_suite", "select_cases"]
