"""Batches and sweeps on Dask: ``tofnet batch PLAN.yaml`` and its Python API (docs/batch.md).

    from tofnet.batch import load_plan, run_batch
    result = run_batch(load_plan("sweep.yaml"), workers=2)
    result.rows        # one dict per task, plan order; result.files: results.csv (.parquet)

Plans need only tofnet; running them needs Dask (``pip install "tofnet[batch]"``).
"""

from __future__ import annotations

from tofnet.batch.plan import NetworkChoice, Plan, PlanError, RecordingSource, load_plan
from tofnet.batch.tasks import Task, expand
from tofnet.errors import TofnetError

#: What ``tofnet batch`` says when Dask is missing.
INSTALL_HINT = "tofnet batch needs Dask (dask.distributed): pip install \"tofnet[batch]\""


def require_dask() -> None:
    """Raise a one-line ``TofnetError`` naming the extra to install when ``distributed`` is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise TofnetError(INSTALL_HINT) from None


def run_batch(plan: Plan, **options):
    """Run ``plan`` on Dask; see ``tofnet.batch.runner.run_batch`` for the options."""
    require_dask()
    from tofnet.batch.runner import run_batch as run
    return run(plan, **options)


__all__ = ["INSTALL_HINT", "NetworkChoice", "Plan", "PlanError", "RecordingSource", "Task", "expand", "load_plan",
           "require_dask", "run_batch"]
