"""Running the time-surface estimator on simulated scenarios and scoring it (shared by the benchmarks).

``run_time_surface(recording, **changes)`` runs ``TimeSurfaceEstimator`` with the
defaults changed by ``changes`` (fields of ``TimeSurfaceConfig``) over the whole recording
(``A t`` from the exact trajectory, one update per 1 ms step, as the paper's network
gets it) and scores it with ``tofnet.eval.metrics.evaluate`` exactly as ``accuracy.py``
scores the paper's network. ``paper_metrics(name, ...)`` is that network's row, cached
as JSON beside the simulations. With ``rotation=True`` both compensate the camera's
rotation (eq. 7, ``ω`` from the recording's trajectory): ``scenario_recording(...,
rotation=True)`` gives a turning scenario as ``accuracy.py`` runs it (poses at 1 kHz,
as ``tofnet run`` reads them) and ``paper_metrics(..., rotation=True)`` the paper
network's eq. 7 row (ω from the poses).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from accuracy import _key, as_written, default_backend, recording_for, run_network, scenario_config  # noqa: E402
from tofnet.models.binding import UpdateRows, angular_velocity_table, velocity_table  # noqa: E402
from tofnet.eval.metrics import evaluate  # noqa: E402
from tofnet.io.recording import Recording  # noqa: E402
from tofnet.io.rotation import PoseAngularVelocity  # noqa: E402
from tofnet.kernels.time_surface_estimator import TimeSurfaceConfig, TimeSurfaceEstimator  # noqa: E402

#: Metric keys of one run, as ``accuracy.Run.metrics`` has them (plus CPU speed).
METRICS = ("events", "estimates", "coverage_pct", "mean_abs_m", "median_abs_m", "mean_rel_pct", "median_rel_pct",
           "bias_pct")


def config_for(recording: Recording, **changes) -> TimeSurfaceConfig:
    k = recording.intrinsics
    return TimeSurfaceConfig(tuple(recording.sensor_size), (k.fx, k.fy, k.cx, k.cy), **changes)


def trajectory_rows(recording: Recording, t0_us: int, config: TimeSurfaceConfig, rotation: bool = False):
    """``VelocityRows`` from the recording's exact trajectory (update j at the start of step j*U),
    computed ahead and cached as a network's velocity process does (``UpdateRows``);
    ``rotation``: six columns, the angular velocity too (eq. 7; from the poses as the angular
    velocity process's ``groundtruth`` source takes it)."""
    trajectory = recording.trajectory
    angular = trajectory
    if rotation and not hasattr(trajectory, "angular_velocity_at"):  # poses: as the process's groundtruth source
        angular = PoseAngularVelocity(trajectory)

    def table(first: int, count: int) -> np.ndarray:
        times = (t0_us, config.timestep_us, config.update_every, count, first)
        rows = velocity_table(trajectory, *times)
        return np.hstack([rows, angular_velocity_table(angular, *times)]) if rotation else rows
    return UpdateRows(table).rows


def run_time_surface(recording: Recording, rotation: bool = False, **changes) -> dict:
    """Metrics of the estimator on ``recording`` (one packet; CPU seconds of the ``feed`` call in ``cpu_s``);
    ``rotation``: eq. 7 with ``ω`` from the recording's trajectory."""
    config = config_for(recording, **changes)
    t0 = int(recording.events["t"][0])
    estimator = TimeSurfaceEstimator(config, t0)
    rows = trajectory_rows(recording, t0, config, rotation)
    start = time.process_time()
    depth, quality = estimator.feed(recording.events, rows)
    cpu = time.process_time() - start
    meta = {"t0_us": t0, "timestep_us": config.timestep_us, "latency_steps": config.latency_steps}
    e = evaluate(recording, depth, meta, window_s=0)
    return {"events": e.events_in, "estimates": e.estimates, "coverage_pct": 100 * e.coverage,
            "mean_abs_m": e.errors.mean_abs_m, "median_abs_m": e.errors.median_abs_m,
            "mean_rel_pct": e.errors.mean_rel_pct, "median_rel_pct": e.errors.median_rel_pct,
            "bias_pct": e.errors.bias_rel_pct, "cpu_s": cpu, "counts": estimator.counts,
            "depth": depth, "quality": quality, "evaluation": e}


def scenario_recording(name: str, duration: float, cache: Path | None, seed: int = 0, rotation: bool = False,
                       **changes) -> Recording:
    """A scenario's recording; ``rotation``: as eq. 7 runs it, with the poses at 1 kHz (``accuracy.as_written``)."""
    config = scenario_config(name, duration, **changes)
    rec = recording_for(config, seed, cache, quiet=False)
    return as_written(rec, config, seed) if rotation else rec


def paper_metrics(name: str, duration: float, cache: Path | None, seed: int = 0, rotation: bool = False) -> dict:
    """The paper's network (defaults, ``accuracy.run_network``) on a scenario, cached as JSON;
    ``rotation``: eq. 7 with ``ω`` from the poses at 1 kHz (``accuracy.as_written``)."""
    config = scenario_config(name, duration)
    eq7 = "-eq7" if rotation else ""
    path = None if cache is None else cache / f"paper-{name}{eq7}-{_key(config, seed)}.json"
    if path is not None and path.exists():
        return json.loads(path.read_text())
    rec = recording_for(config, seed, cache, quiet=True)
    if rotation:
        rec = as_written(rec, config, seed)
    r = run_network(rec, backend=default_backend(), rotation="groundtruth" if rotation else None)
    m = {key: float(value) for key, value in r.metrics().items() if key in METRICS}
    if path is not None:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(m))
        tmp.replace(path)
    return m

