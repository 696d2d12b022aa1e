"""What runs on a worker: simulate a scenario into the cache, run one task, warm the kernels up.

Nothing here needs Dask: ``run_task`` is a plain function of a ``Task`` and a path, so
a worker reads its recording itself (the client never ships events). A task writes
its files to a hidden temporary name and renames them when whole, and writes its
``row.json`` last: a task folder with a ``row.json`` of status ``ok`` is complete.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import time
import uuid
from contextlib import nullcontext
from pathlib import Path
from typing import Any

from tofnet.batch.tasks import SCENARIO_FILE, Task
from tofnet.errors import TofnetError, fields_shown_within
from tofnet.io.files import write_text_atomic
from tofnet.io.guard import reading

ROW_FILE = "row.json"
DEPTH_FILE = "depth.npz"
SUMMARY_FILE = "summary.json"


def simulate_scenario(task: Task) -> str:
    """Simulate ``task``'s scenario into its cache folder unless it is there; the folder.

    The simulation goes to a temporary folder renamed into place when complete, so
    two workers racing on one scenario, or a worker killed half-way, leave either
    nothing or a whole recording under the final name.
    """
    from tofnet.sim.run import simulate

    final = Path(task.scenario_folder)
    if (final / SCENARIO_FILE).is_file():
        return str(final)
    source = task.recording
    tmp = final.with_name(f".{final.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    try:
        summary = simulate(source.scenario, tmp, duration=source.duration, seed=source.seed,
                           sensor_size=source.sensor_size)
        (tmp / SCENARIO_FILE).write_text(json.dumps(summary, indent=2, default=str) + "\n", encoding="utf-8")
        try:
            os.rename(tmp, final)
        except OSError:
            if not (final / SCENARIO_FILE).is_file():  # not another worker's finished copy: a real error
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return str(final)


def base_row(task: Task) -> dict[str, Any]:
    """The input columns of ``task``'s row."""
    from tofnet.batch.tasks import _plain
    source = task.recording
    return {"task": task.number, "task_id": task.task_id, "recording": source.label,
            "recording_name": source.name, "scenario": source.scenario,
            "seed": source.seed if source.scenario else None,
            "duration_s": source.duration if source.scenario else None,
            "network": task.network.name, "backend": task.backend,
            **{k: _plain(v) for k, v in task.params}}


def run_task(task: Task, recording_path: str | None = None) -> dict[str, Any]:
    """Run one task (as ``tofnet run`` would) and write its outputs; its table row.

    Never raises for a bad recording, spec or parameter, or for running out of
    memory: the row then has ``status`` ``failed`` and the one-line ``error``.
    """
    started, cpu_started = time.perf_counter(), time.thread_time()
    row = {**base_row(task), "status": "failed", "error": None, "worker": worker_name(),
           "fingerprint": task.fingerprint}
    folder = Path(task.folder)
    try:
        shown = fields_shown_within(task.plan_folder, "the plan's folder") if task.plan_folder else nullcontext()
        with reading(), shown:  # what the task reads, which none of its outputs may replace
            row.update(_run(task, recording_path or task.recording_path, folder))
        row["status"] = "ok"
    except MemoryError:
        row["error"] = "out of memory while running the task"
    except TofnetError as err:
        row["error"] = one_line(str(err))
    except Exception as err:  # a bug or an unreadable file: the batch goes on, the row says what happened
        row["error"] = one_line(f"{type(err).__name__}: {err}")
    row["task_time_s"] = time.perf_counter() - started
    row["cpu_time_s"] = time.thread_time() - cpu_started  # below task_time_s when the machine is busy
    row["keep"] = list(task.keep)
    write_json(folder / ROW_FILE, row)
    return row


def _run(task: Task, recording_path: str, folder: Path) -> dict[str, Any]:
    from tofnet.api import DEFAULT_BACKEND, apply_overrides, load_network, run
    from tofnet.io.source import open_recording

    from tofnet.batch.grid import BACKEND_KEYS
    from tofnet.batch.reading import open_options

    options = task.recording.options
    with open_recording(recording_path, **open_options(options)) as source:
        recording = source.read()
        window = source.window  # absolute µs, recorded for eval and plot of the depth file
    # The same network `tofnet run RECORDING [--spec S | --estimator E] [--refractory R ...] [--velocity V]` builds:
    # the recording decides the default network's rotation (eq. 7 when it turns) and is checked against
    # a spec's lens handling.
    network, compile_options, spec_backend, backend_options = load_network(
        task.network.spec, sensor_size=None if task.network.spec else recording.sensor_size,
        recording=recording, rotation=task.network.rotation, undistort=task.network.undistort,
        estimator=task.network.estimator, allow_import=task.network.allow_import)
    parameters = {k: v for k, v in task.parameters.items() if k not in BACKEND_KEYS}
    apply_overrides(network, **parameters)
    if options.get("velocity"):
        from tofnet.api import constant_velocity
        constant_velocity(network, options["velocity"])
    backend = task.backend or spec_backend or DEFAULT_BACKEND
    if task.backend and task.backend != spec_backend:
        backend_options = {}  # the spec's options belong to the spec's backend
    backend_options = {**backend_options, **{k: v for k, v in task.parameters.items() if k in BACKEND_KEYS}}
    result, _ = run(recording, network, backend=backend, backend_options=backend_options,
                    compile_options=compile_options)
    summary = result.summary()
    summary["recording"] = recording_path
    if window is not None:
        summary["window_us"] = list(window)
    from tofnet.api import lens_of_run, rotation_line, undistortion_of

    summary["rotation"] = rotation_line(network, recording, no_rotation=not task.network.rotation)
    summary["undistortion"] = undistortion_of(network, recording, result, recording_path,
                                              no_undistort=not task.network.undistort)
    summary["notes"] = list(recording.notes)
    lens = lens_of_run(summary["undistortion"])  # the estimates' pixels are undistorted: scored and recorded so
    out: dict[str, Any] = {
        "backend": backend, "notes": "; ".join(summary["notes"]) or None,  # what the reader left out, and why
        "events_in": summary["events_in"], "accepted": summary["accepted"],
        "dropped": sum(summary["dropped"].values()),
        **{f"dropped_{r}": n for r, n in summary["dropped"].items()},  # the first reader's reasons
        "tot_spikes": summary["tot_spikes"], "depth_out": summary.get("depth_out"),
        **{f"rejected_{r}": n for r, n in summary.get("rejected", {}).items()},
        "steps": summary["steps"], "latency_steps": summary["latency_steps"],
        **{f"latency_{output}": steps for output, steps in summary["latency"].items()},  # per output port
        "wall_time_s": summary["wall_time_s"],
        "events_per_s": summary["events_in"] / summary["wall_time_s"] if summary["wall_time_s"] > 0 else None,
    }
    meta = {"t0_us": result.t0_us, "timestep_us": result.timestep_us, "latency_steps": result.latency_steps}
    if "metrics" in task.keep and recording.gt_depth is not None:
        from tofnet.eval.metrics import evaluate
        scored = recording if lens is None else _undistorted(recording, lens, recording_path)
        evaluation = evaluate(scored, result.depth, meta)
        e = evaluation.errors
        out.update(matched=e.n, coverage_pct=_pct(evaluation.coverage), mean_abs_m=_num(e.mean_abs_m),
                   median_abs_m=_num(e.median_abs_m), mean_rel_pct=_num(e.mean_rel_pct),
                   median_rel_pct=_num(e.median_rel_pct), bias_rel_pct=_num(e.bias_rel_pct),
                   **{k: _num(v) for k, v in evaluation.cutoffs.items()})
        from tofnet.eval.breakdown import breakdown_columns
        out.update(breakdown_columns(result.depth, evaluation.matches, scored))
        summary["evaluation"] = evaluation.to_dict()
    if "depth" in task.keep:
        from tofnet.io.depth import write_depth
        write_depth(folder / DEPTH_FILE, result.depth, summary={**summary, "undistortion": lens}, **meta)  # atomic
        out["depth_file"] = str(folder / DEPTH_FILE)
    if "summary" in task.keep:
        summary["parameters"] = task.parameters
        write_json(folder / SUMMARY_FILE, summary)
        out["summary_file"] = str(folder / SUMMARY_FILE)
    return out


def _undistorted(recording, lens: dict, path: str):
    """``recording`` with its events moved through ``lens`` (``tofnet eval`` of a depth file that records one)."""
    from tofnet.eval.undistorted import lens_from_summary, undistorted_recording
    if recording.frame_gt is not None and recording.frame_gt.pixel_map is not None:
        from tofnet.errors import DataError
        raise DataError(f"{path}: the estimates are at undistorted pixels, the ground truth is placed through the "
                        "rectification map from raw pixels; use rectify: true and a network without an undistort "
                        "process instead")
    return undistorted_recording(recording, *lens_from_summary(lens))


def is_complete(task: Task) -> dict | None:
    """``task``'s row when its outputs are all there from an earlier, successful run; else ``None``."""
    folder = Path(task.folder)
    from tofnet.io.jsontext import parse_json
    try:
        row = parse_json((folder / ROW_FILE).read_text(encoding="utf-8"), folder / ROW_FILE)
    except (OSError, ValueError, TofnetError):  # unreadable: the task runs again
        return None
    if not isinstance(row, dict) or row.get("status") != "ok" or row.get("task_id") != task.task_id:
        return None
    if row.get("fingerprint") != task.fingerprint:  # the recording's (or spec's) content changed since
        return None
    if not set(task.keep) <= set(row.get("keep", ())):  # the plan now keeps more than that run did
        return None
    files = {"depth": DEPTH_FILE, "summary": SUMMARY_FILE}
    if any(not (folder / files[k]).is_file() for k in task.keep if k in files):
        return None
    return {**row, "task": task.number}


def warm_up(backends: tuple[str, ...] = ("fixed",)) -> float:
    """Load (or compile) the numba kernels of a task in this process: read, run and score a tiny recording; seconds."""
    import tempfile

    import numpy as np

    from tofnet.api import run
    from tofnet.eval.metrics import evaluate
    from tofnet.io import read_recording
    from tofnet.io.ecd import write_ecd
    from tofnet.io.recording import Intrinsics
    from tofnet.networks import depth_network
    from tofnet.testing import moving_edge

    started = time.perf_counter()
    size = (16, 12)
    events = moving_edge(size, -50.0, "u")
    with tempfile.TemporaryDirectory(prefix="tofnet-warm-up-") as folder:
        write_ecd(folder, events, intrinsics=Intrinsics(20.0, 20.0, 7.5, 5.5), times=np.array([0.0, 1.0]),
                  positions=np.array([[0.0, 0, 0], [0.5, 0, 0]]), quaternions=np.array([[0.0, 0, 0, 1]] * 2),
                  sensor_size=size, gt_depth=np.full(len(events), 0.2))
        recording = read_recording(folder)
    for backend in backends:
        result, _ = run(recording, depth_network(size), backend=backend)
    evaluate(recording, result.depth, {"t0_us": result.t0_us, "timestep_us": result.timestep_us,
                                       "latency_steps": result.latency_steps})
    return time.perf_counter() - started


def write_json(path: Path, data: dict) -> None:
    write_text_atomic(path, json.dumps(data, indent=2, default=str, allow_nan=False) + "\n")


def worker_name() -> str:
    """The Dask worker's address, or ``host:pid`` outside Dask."""
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"


def one_line(message: str) -> str:
    lines = [line.strip() for line in message.strip().splitlines() if line.strip()]
    return lines[0] if lines else "error without a message"


def _num(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def _pct(share: float) -> float | None:
    return None if share is None or not math.isfinite(share) else 100.0 * share
