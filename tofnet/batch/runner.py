"""Run a plan's tasks on Dask: a local cluster by default, or an existing scheduler.

Each task is one ``distributed`` future; a simulated scenario is one more future its
runs depend on. A task that fails returns a failed row (the batch goes on); a worker
that dies is restarted by its nanny and the scheduler reruns its tasks (up to
``distributed.scheduler.allowed-failures`` times, then the row says so). Ctrl-C
cancels what is left and closes the cluster; ``resume=True`` skips finished tasks.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import dask
from distributed import Client, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin

from tofnet.batch.outputs import check_batch_output, fingerprint, mark_output
from tofnet.batch.plan import Plan
from tofnet.batch.table import plot, sort_rows, write_table
from tofnet.batch.tasks import Task, expand
from tofnet.batch.worker import ROW_FILE, base_row, is_complete, one_line, run_task, simulate_scenario, warm_up, \
    write_json
from tofnet.errors import TofnetError
from tofnet.machine import cpu_count

#: Seconds between progress lines on a terminal (a log gets one line every ``LOG_EVERY``).
TTY_EVERY, LOG_EVERY = 0.5, 10.0
#: Seconds to reach a scheduler, and to wait for its first worker.
CONNECT_TIMEOUT_S, WAIT_FOR_WORKERS_S = 10, 60
#: Seconds between two counts of running tasks (each asks the scheduler).
REPORT_EVERY_S = 0.25
#: Seconds to fetch a finished task's row from its worker.
RESULT_TIMEOUT_S = 10


@dataclass
class BatchResult:
    """What a batch did: every row (plan order), the files written, and counts.

    ``wall_time_s`` covers everything (cluster start-up, tasks, table, plot);
    ``tasks_time_s`` the tasks alone, from the first submission to the last row.
    """

    plan: Plan
    rows: list[dict]
    files: list[Path] = field(default_factory=list)
    plot: Path | None = None
    resumed: int = 0
    wall_time_s: float = 0.0
    tasks_time_s: float = 0.0
    workers: int = 0

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r.get("status") != "ok"]


class WarmUp(WorkerPlugin):
    """Loads the numba kernels when a worker starts (and when a dead one is replaced), not in its first task."""

    idempotent = True  # registered again by the next batch on the same cluster: nothing to do

    def __init__(self, backends: tuple[str, ...], ignore_sigint: bool = False):
        self.backends, self.ignore_sigint = backends, ignore_sigint
        self.name = "tofnet-warm-up-" + "-".join(backends)

    def setup(self, worker) -> None:
        if self.ignore_sigint and threading.current_thread() is threading.main_thread():
            # A local cluster's workers share the terminal's Ctrl-C; the client stops them cleanly.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            worker.tofnet_warm_up_s = warm_up(self.backends)
        except Exception as err:  # a warm-up failure must not stop the worker: its first task compiles instead
            logging.getLogger("tofnet.batch").warning("warm-up failed: %s", one_line(str(err)))


def local_cluster(workers: int | None = None, memory_limit: str | float | None = "auto") -> LocalCluster:
    """One single-threaded worker process per core (or ``workers``) on loopback, no HTTP server, and only
    this process may use it: mutual TLS with certificates made for it (another local user could otherwise
    connect to the scheduler and run code on the workers as the user who started the batch).

    ``memory_limit`` per worker: ``"auto"`` shares the machine's memory equally, a
    number is bytes, a string like ``"2GB"``. A worker over 95 % of it is restarted.
    """
    n = workers or cpu_count()
    # Dask starts an HTTP server whatever the dashboard setting: on loopback, and serving nothing (no routes)
    no_pages = {"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []}
    with _sigint_ignored(), dask.config.set(no_pages):  # SIG_IGN is inherited: Ctrl-C reaches the client only
        return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, memory_limit=memory_limit,
                            host="127.0.0.1", dashboard_address="127.0.0.1:0", security=True,
                            silence_logs=logging.CRITICAL)


@contextlib.contextmanager
def _sigint_ignored():
    """Ignore SIGINT while processes are started (it stays ignored in them); restore it after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def _connect(scheduler: str | None, workers: int | None, memory_limit):
    """A client of the scheduler at ``scheduler``, or of a new local cluster closed on exit."""
    if scheduler is not None:
        try:
            client = Client(scheduler, set_as_default=False, timeout=f"{CONNECT_TIMEOUT_S}s")
        except (OSError, TimeoutError, ValueError) as err:
            raise TofnetError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there "
                              f"({one_line(str(err)) or type(err).__name__})") from None
        with client:
            yield client
        return
    with local_cluster(workers, memory_limit) as cluster, Client(cluster, set_as_default=False) as client:
        yield client


def run_batch(plan: Plan, *, scheduler: str | None = None, workers: int | None = None,
              memory_limit: str | float | None = "auto", resume: bool = False, force: bool = False,
              fingerprints: str = "sample", client: Client | None = None,
              progress: Callable[[dict], None] | None = None) -> BatchResult:
    """Run every task of ``plan`` and write the table and the plot to ``plan.output``.

    The output folder is checked before anything runs (``tofnet.batch.outputs``): an
    earlier batch's folder needs ``resume`` (run only what is missing, or whose input
    files' content changed: ``fingerprints`` ``"sample"`` or ``"full"``) or ``force``
    (run every task again); a folder holding anything else is refused.

    ``client`` (an open ``distributed.Client``) or ``scheduler`` (an address) use an
    existing cluster; otherwise a ``local_cluster(workers, memory_limit)`` is started
    and closed. ``progress`` receives a dict of counts now and then (see ``Progress``).
    Ctrl-C cancels the remaining tasks and raises ``KeyboardInterrupt``; finished
    tasks stay on disk for ``resume``.
    """
    started = time.perf_counter()
    tasks = expand(plan)
    check_batch_output(plan, force=force, resume=resume)
    memo: dict[str, str] = {}
    tasks = [replace(t, fingerprint=fingerprint(t, fingerprints, memo)) for t in tasks]
    mark_output(plan)
    done: dict[int, dict] = {}
    if resume:
        done = {t.number: row for t in tasks if (row := is_complete(t)) is not None}
    todo = [t for t in tasks if t.number not in done]
    resumed = len(done)
    n_workers, tasks_time = 0, 0.0
    if todo:
        with contextlib.ExitStack() as stack:
            active = client or stack.enter_context(_connect(scheduler, workers, memory_limit))
            try:
                active.wait_for_workers(1, timeout=WAIT_FOR_WORKERS_S)
            except TimeoutError:
                raise TofnetError(f"no Dask worker joined the scheduler at {active.scheduler.address} within "
                                  f"{WAIT_FOR_WORKERS_S:g} s; start some with: dask worker ADDRESS") from None
            from tofnet.batch.probe import check_cluster
            check_cluster(active)  # one line naming a scheduler or worker without tofnet, before any task
            backends = tuple(sorted({t.backend or "fixed" for t in todo}))
            plugin = WarmUp(backends, ignore_sigint=client is None and scheduler is None)
            active.register_plugin(plugin)
            if client is not None or scheduler is not None:
                # Left registered, it would be sent to every worker that joins the cluster later, and one
                # without tofnet could not even start: an existing cluster is given back as it was.
                stack.callback(_unregister, active, plugin.name)
            n_workers = len(active.scheduler_info()["workers"])
            execution = _Execution(active, todo, done, progress, len(tasks))
            execution.run()
            tasks_time = time.perf_counter() - execution.started
    rows = sort_rows(done.values())
    parameters = list(plan.grid)
    files = write_table(rows, parameters, plan.output)
    figure = plot(rows, parameters, plan.output / "plot.png")
    return BatchResult(plan, rows, files, figure, resumed, time.perf_counter() - started, tasks_time, n_workers)


def _unregister(client: Client, name: str) -> None:
    try:
        client.unregister_worker_plugin(name)
    except Exception:  # the cluster is gone or busy: nothing left to give back
        pass


class _Execution:
    """Submits the tasks, collects rows as they finish, reports progress."""

    def __init__(self, client: Client, tasks: list[Task], done: dict[int, dict],
                 progress: Callable[[dict], None] | None, total: int):
        self.client, self.tasks, self.done, self.progress, self.total = client, tasks, done, progress, total
        self.token = uuid.uuid4().hex[:8]  # keys unique on a shared scheduler
        self.events = 0
        self.simulations: dict[int, Any] = {}  # task number -> the future simulating its scenario
        self.started = time.perf_counter()
        self.reported = -1e9

    def submit(self) -> dict[Any, Task]:
        simulations = {}
        futures = {}
        for task in self.tasks:
            source = None
            if task.scenario_folder is not None:
                if task.scenario_folder not in simulations:
                    simulations[task.scenario_folder] = self.client.submit(
                        simulate_scenario, task, key=f"tofnet-simulate-{Path(task.scenario_folder).name}-{self.token}",
                        priority=1, pure=False)
                source = simulations[task.scenario_folder]
                self.simulations[task.number] = source
            future = self.client.submit(run_task, task, source, key=f"tofnet-{task.task_id}-{self.token}",
                                        priority=-task.number, pure=False)
            futures[future] = task
        return futures

    def run(self) -> None:
        pending = self.submit()
        failed = 0
        try:
            while pending:
                finished = [f for f in pending if f.done()]
                for future in finished:
                    row = self.collect(future, pending[future])
                    if row is None:  # its result was lost with a worker: the scheduler computes it again
                        continue
                    task = pending.pop(future)
                    failed += row.get("status") != "ok"
                    self.events += row.get("events_in") or 0
                    self.done[task.number] = row
                if self.progress is not None and (not pending or time.perf_counter() - self.reported >= REPORT_EVERY_S):
                    self.report(pending, failed, final=not pending)
                if not finished:
                    time.sleep(0.1)
        except KeyboardInterrupt:
            self.client.cancel(list(pending), force=True)
            raise

    def collect(self, future, task: Task) -> dict | None:
        """The row of a done future, or ``None`` when its result is being computed again."""
        status = future.status
        if status == "finished":
            try:
                return future.result(timeout=RESULT_TIMEOUT_S)
            except Exception:  # lost with its worker after done(): the scheduler reruns the task
                return None
        if status not in ("error", "cancelled"):
            return None
        if status == "cancelled":
            error = "cancelled by the scheduler"
        else:
            exc = future.exception()
            kind = type(exc).__name__
            if kind == "KilledWorker":
                error = f"KilledWorker: the worker died every time it ran this task ({one_line(str(exc))})"
            elif isinstance(exc.__cause__, ImportError):  # a process that joined later without tofnet
                error = f"Dask could not load the task ({type(exc.__cause__).__name__}: {exc.__cause__}); " \
                        "install tofnet on every worker and the scheduler"
            else:
                error = one_line(f"{kind}: {exc}")
            simulation = self.simulations.get(task.number)
            if simulation is not None and simulation.status == "error":
                error = f"simulating {task.recording.scenario}: {error}"
        row = {**base_row(task), "status": "failed", "error": error, "keep": list(task.keep)}
        try:
            write_json(Path(task.folder) / ROW_FILE, row)
        except (OSError, TofnetError):
            pass  # the table still gets the row
        return row

    def report(self, pending: dict, failed: int, final: bool) -> None:
        try:
            keys = {f.key for f in pending}
            threads = self.client.nthreads()
            running = sum(min(threads.get(worker, 1), sum(k in keys for k in ks))
                          for worker, ks in self.client.processing().items())
        except Exception:  # the scheduler is busy or gone: progress is not worth failing for
            running = 0
        self.reported = time.perf_counter()
        elapsed = self.reported - self.started
        self.progress({"done": len(self.done), "failed": failed, "running": running, "total": self.total,
                       "waiting": len(pending) - running, "events": self.events, "elapsed_s": elapsed,
                       "events_per_s": self.events / elapsed if elapsed > 0 else 0.0, "final": final})


class Progress:
    """Progress on stderr: tasks done/failed/running and events per second across the cluster."""

    def __init__(self, stream=None):
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.last = -1e9

    def __call__(self, counts: dict) -> None:
        now = time.perf_counter()
        if not counts["final"] and now - self.last < (TTY_EVERY if self.tty else LOG_EVERY):
            return
        self.last = now
        line = (f"tofnet batch: {counts['done']}/{counts['total']} done ({counts['failed']} failed), "
                f"{counts['running']} running, {counts['waiting']} waiting; "
                f"{counts['events_per_s'] / 1e6:.2f} M events/s, {counts['elapsed_s']:.1f} s")
        end = "\n" if counts["final"] or not self.tty else ""
        self.stream.write(("\r" + line + end) if self.tty else line + "\n")
        self.stream.flush()
