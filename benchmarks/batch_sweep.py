"""The refractory sweep through ``tofnet batch``: 1 vs 2 local Dask workers, measured in one run (by hand, not CI).

    python benchmarks/batch_sweep.py
    python benchmarks/batch_sweep.py --scenarios slider,vertical --values 5,20,60 --duration 0.3 --serial

Does what ``refractory_sweep.py`` does (every built-in scenario x refractory periods,
the paper's network, metrics against the simulated depth) as one ``tofnet batch``
plan, on fresh local clusters of each worker count (``--workers``, default ``1,2``),
``--repeat`` times in the order 1, 2, 2, 1, keeping each count's fastest run. The
scenarios are simulated first into a shared cache, outside the timings.

It prints, per worker count: the cluster start-up (processes, imports and each
worker's numba warm-up), the tasks (first submission to last row), the tasks' CPU
time, CPU share and CPU bound (the tasks' CPU time over the busiest worker's: the
speed-up the division of the work allows when each worker has a core), writing the table and the plot, the total, and the speed-ups
against the first count; then the load average before and after and how many cores
1 and 2 busy-looping processes get at those moments (on a shared machine, 2 workers
cannot go faster than the cores they get), whether the tables are identical apart
from timing columns, and the median relative error per scenario and period.
``--serial`` adds the same tasks one by one in this process without Dask (interleaved
like the others); ``--cold`` the time a new process takes to warm up with and without
numba's disk cache.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from tofnet.batch import expand, load_plan
from tofnet.batch.table import TIMING_COLUMNS, read_csv
from tofnet.sim import built_in_scenarios

VALUES_MS = "20,40,60,100"


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def plan_text(scenarios: list[str], values: list[str], duration: float, size: str, seed: int, cache: Path,
              output: Path) -> str:
    return (f"name: batch-sweep\noutput: {output}\ncache: {cache}\n"
            f"recordings:\n  - scenario: [{', '.join(scenarios)}]\n    duration: {duration}\n"
            f"    sensor_size: {size}\n    seed: {seed}\n"
            f"grid:\n  refractory: [{', '.join(v + 'ms' for v in values)}]\nkeep: [metrics]\n")


def timed_batch(text: str, workers: int) -> dict:
    """Start a local cluster of ``workers``, warm it up, run the plan; seconds of each part."""
    from distributed import Client

    from tofnet.batch import run_batch
    from tofnet.batch.runner import WarmUp, local_cluster

    started = time.perf_counter()
    with local_cluster(workers) as cluster, Client(cluster, set_as_default=False) as client:
        client.register_plugin(WarmUp(("fixed",), ignore_sigint=True))
        warm = client.run(lambda dask_worker: getattr(dask_worker, "tofnet_warm_up_s", float("nan")))
        ready = time.perf_counter()
        result = run_batch(load_plan(text), client=client)
        finished = time.perf_counter()
    return {"workers": workers, "startup_s": ready - started, "batch_s": result.tasks_time_s,
            "table_s": finished - ready - result.tasks_time_s,
            "total_s": finished - started, "warm_up_s": sorted(warm.values()), "result": result,
            "first_task_s": result.rows[0]["task_time_s"], "cpu_s": sum(r["cpu_time_s"] for r in result.rows),
            "busiest_cpu_s": max(sum(r["cpu_time_s"] for r in result.rows if r["worker"] == w)
                                 for w in {r["worker"] for r in result.rows}),
            "median_task_s": statistics.median(r["task_time_s"] for r in result.rows)}


def serial(text: str) -> dict:
    """The same tasks one by one in this process (no Dask), after warming the kernels up here."""
    from tofnet.batch.worker import run_task, warm_up

    started = time.perf_counter()
    warm_up()
    ready = time.perf_counter()
    for task in expand(load_plan(text)):
        run_task(task)
    finished = time.perf_counter()
    return {"workers": "serial", "startup_s": ready - started, "batch_s": finished - ready, "table_s": 0.0,
            "total_s": finished - started}


def _spin(seconds: float) -> float:
    started, cpu = time.perf_counter(), time.process_time()
    while time.perf_counter() - started < seconds:
        pass
    return time.process_time() - cpu


def free_cores(seconds: float = 3.0) -> list[float]:
    """Cores the machine gives 1, then 2, busy-looping processes now (2.0 on an idle 2-core machine)."""
    from multiprocessing import get_context
    shares = []
    for n in (1, 2):
        with get_context("spawn").Pool(n) as pool:
            shares.append(sum(pool.map(_spin, [seconds] * n)) / seconds)
    return shares


def fresh_warm_up(cold: bool) -> float:
    """Seconds a new process takes to import tofnet and warm its kernels up, from numba's disk cache or cold."""
    import subprocess
    env = dict(os.environ)
    with tempfile.TemporaryDirectory(prefix="tofnet-numba-") as empty:
        if cold:
            env["NUMBA_CACHE_DIR"] = empty  # nothing cached: every kernel compiles
        code = ("import time; t = time.perf_counter(); from tofnet.batch.worker import warm_up; warm_up(); "
                "print(time.perf_counter() - t)")
        done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(done.stdout.split()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default=",".join(built_in_scenarios()))
    parser.add_argument("--values", default=VALUES_MS, help=f"refractory periods in ms (default {VALUES_MS})")
    parser.add_argument("--duration", type=float, default=0.5, help="seconds per scenario (default 0.5)")
    parser.add_argument("--size", default="240x180")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", default="1,2", help="worker counts to compare (default 1,2)")
    parser.add_argument("--repeat", type=int, default=2,
                        help="runs per worker count, in the order 1,2,2,1,...; the fastest counts (default 2)")
    parser.add_argument("--serial", action="store_true", help="also run the tasks in this process without Dask")
    parser.add_argument("--cold", action="store_true",
                        help="also time a new process's warm-up with numba's disk cache and without it")
    parser.add_argument("--cache", default=str(Path(tempfile.gettempdir()) / "tofnet-batch-sweep"))
    args = parser.parse_args(argv)
    scenarios = [s for s in args.scenarios.split(",") if s]
    values = [v for v in args.values.split(",") if v]
    counts = [int(n) for n in args.workers.split(",")]
    cache = Path(args.cache)
    out = Path(tempfile.mkdtemp(prefix="tofnet-batch-sweep-"))
    texts = {n: plan_text(scenarios, values, args.duration, args.size, args.seed, cache, out / f"w{n}")
             for n in [*counts, "serial"]}
    n_tasks = len(expand(load_plan(texts[counts[0]])))
    log(f"batch sweep: {len(scenarios)} scenarios x {len(values)} periods = {n_tasks} tasks, {args.duration:g} s "
        f"at {args.size}; workers {counts}; {os.cpu_count()} cores")

    from distributed import Client

    from tofnet.batch.runner import local_cluster
    from tofnet.batch.worker import simulate_scenario
    primed = time.perf_counter()
    todo = {t.scenario_folder: t for t in expand(load_plan(texts[counts[0]]))}
    with local_cluster(max(counts)) as cluster, Client(cluster, set_as_default=False) as client:
        client.gather(client.map(simulate_scenario, list(todo.values()), pure=False))
    log(f"  scenarios ready in {cache} ({time.perf_counter() - primed:.1f} s)")

    load_before = os.getloadavg()
    cores_before = free_cores()
    configs: list = [*counts, *(["serial"] if args.serial else [])]
    # 1, 2, serial, serial, 2, 1, ...: a load that drifts during the runs hits every configuration alike
    order = [c for i in range(args.repeat) for c in (configs if i % 2 == 0 else configs[::-1])]
    every: dict = {c: [] for c in configs}
    for c in order:
        r = serial(texts["serial"]) if c == "serial" else timed_batch(texts[c], c)
        every[c].append(r)
        cpu = f", task CPU {r['cpu_s']:.1f} s" if "cpu_s" in r else ""
        log(f"  {c if c == 'serial' else f'{c} worker(s)'}: start-up {r['startup_s']:.1f} s, tasks {r['batch_s']:.1f} s{cpu}, "
            f"load {os.getloadavg()[0]:.2f}")
    runs = [min(every[c], key=lambda r: r["batch_s"]) for c in configs]
    load_after = os.getloadavg()
    cores_after = free_cores()

    base = runs[0]
    print(f"Refractory sweep through tofnet batch: {len(scenarios)} scenarios x {len(values)} periods "
          f"({', '.join(values)} ms) = {n_tasks} tasks, {args.duration:g} s each at {args.size}, seed {args.seed}; "
          f"{os.cpu_count()} cores")
    print(f"load average before {' '.join(f'{x:.2f}' for x in load_before)}, "
          f"after {' '.join(f'{x:.2f}' for x in load_after)} (1, 5, 15 min)")
    print(f"cores that 1 and 2 busy-looping processes got (3 s each): before {cores_before[0]:.2f} and "
          f"{cores_before[1]:.2f}, after {cores_after[0]:.2f} and {cores_after[1]:.2f}")
    print()
    if args.cold:
        cached, cold = fresh_warm_up(False), fresh_warm_up(True)
        print(f"new process, import + warm-up: {cached:.2f} s from numba's disk cache, {cold:.2f} s compiling "
              f"(empty NUMBA_CACHE_DIR)")
    each = "; ".join(f"{c}: " + ", ".join(f"{r['batch_s']:.1f}" for r in every[c]) for c in configs)
    print(f"fastest of {args.repeat} run(s) per configuration (tasks s of every run: {each})")
    print()
    print("(CPU share: the tasks' CPU time over tasks s x workers, below 100 % when other processes hold the "
          "cores; CPU bound: the tasks' CPU time over the busiest worker's, the speed-up the split of the work "
          "allows when every worker has a core of its own)")
    print(f"{'workers':>8} {'start-up s':>11} {'tasks s':>9} {'task CPU s':>11} {'CPU share':>10} {'table+plot s':>13} "
          f"{'total s':>9} {'CPU bound':>10} {'tasks speed-up':>15} {'total speed-up':>15} {'warm-up s per worker':>22} "
          f"{'first / median task s':>22}")
    for r in runs:
        warm = " ".join(f"{w:.2f}" for w in r.get("warm_up_s", [])) or "-"
        tasks = f"{r['first_task_s']:.2f} / {r['median_task_s']:.2f}" if "first_task_s" in r else "-"
        bound = f"{r['cpu_s'] / r['busiest_cpu_s']:9.2f}x" if "cpu_s" in r else f"{'-':>10}"
        cpu = f"{r['cpu_s']:11.2f} {100 * r['cpu_s'] / (r['batch_s'] * r['workers']):9.0f}%" if "cpu_s" in r \
            else f"{'-':>11} {'-':>10}"
        print(f"{r['workers']!s:>8} {r['startup_s']:11.2f} {r['batch_s']:9.2f} {cpu} {r['table_s']:13.2f} "
              f"{r['total_s']:9.2f} {bound} {base['batch_s'] / r['batch_s']:14.2f}x {base['total_s'] / r['total_s']:14.2f}x "
              f"{warm:>22} {tasks:>22}")
    tables = [[{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in read_csv(r["result"].files[0])]
              for r in runs if "result" in r]
    print(f"\ntables identical apart from {', '.join(TIMING_COLUMNS)}: "
          f"{'yes' if all(t == tables[0] for t in tables) else 'NO'}")
    failed = [r for r in base["result"].rows if r["status"] != "ok"]
    if failed:
        print(f"failed tasks: {len(failed)}, e.g. {failed[0]['task_id']}: {failed[0]['error']}")
    print(f"\nmedian relative error, % ({counts[0]}-worker table)")
    print(f"{'scenario':>15} " + " ".join(f"{v + ' ms':>8}" for v in values))
    for s in scenarios:
        cells = {r["refractory"]: r.get("median_rel_pct") for r in base["result"].rows if r["scenario"] == s}
        print(f"{s:>15} " + " ".join(f"{cells.get(v + 'ms') or float('nan'):8.1f}" for v in values))
    cmd = "python benchmarks/batch_sweep.py"
    for flag, value, default in (("--scenarios", args.scenarios, ",".join(built_in_scenarios())),
                                 ("--values", args.values, VALUES_MS), ("--duration", args.duration, 0.5),
                                 ("--size", args.size, "240x180"), ("--seed", args.seed, 0),
                                 ("--workers", args.workers, "1,2"), ("--repeat", args.repeat, 2)):
        if value != default:
            cmd += f" {flag} {value}"
    cmd += " --serial" * args.serial + " --cold" * args.cold
    print(f"\nreproduce: {cmd}   (outputs in {out})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
