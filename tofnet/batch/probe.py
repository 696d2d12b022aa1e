"""Can the cluster's processes import tofnet? Asked before any task is sent.

Dask unpickles a task on its worker and, since 2023, its graph on the scheduler too; a
process without tofnet (or one of its dependencies) then fails every task with "Error
during deserialization of the task graph", and the traceback lands in its log. So
``check_cluster`` runs ``can_import`` on the scheduler and every worker first. This module
imports nothing from tofnet and is sent *by value* (cloudpickle), so the probe itself runs
where tofnet is missing.
"""

from __future__ import annotations

#: What a task needs on a worker (and the scheduler, to unpickle it).
NEEDED = "tofnet.batch.worker"


def can_import(module: str = NEEDED) -> str | None:
    """``None`` when ``module`` imports here, else ``"package (error)"`` naming the missing package."""
    import importlib

    try:
        importlib.import_module(module)
    except ImportError as err:
        missing = getattr(err, "name", None) or module.split(".")[0]
        return f"{missing.split('.')[0]} ({type(err).__name__}: {err})"
    except Exception as err:  # a broken install: say so, in one line
        return f"{module.split('.')[0]} ({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})"
    return None


def check_cluster(client) -> None:
    """Raise a one-line ``TofnetError`` when the scheduler or a worker cannot import tofnet."""
    import sys

    import cloudpickle

    from tofnet.errors import TofnetError

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the probe travels as code, not as a name
    try:
        problems = [("scheduler", client.scheduler.address, client.run_on_scheduler(can_import))]
        problems += [("worker", address, answer) for address, answer in sorted(client.run(can_import).items())]
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    bad = [(kind, address, answer) for kind, address, answer in problems if answer]
    if bad:
        kind, address, answer = bad[0]
        others = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise TofnetError(f"the Dask {kind} {address}{others} cannot import {answer}; install tofnet and its "
                          f"dependencies there (pip install \"tofnet[batch]\", the same version as here)")
