"""``simulate``: a scenario (or config) to an ECD folder with ground-truth depth, and its summary."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from tofnet.sim.config import SimConfig
from tofnet.sim.engine import generate
from tofnet.sim.errors import SimError
from tofnet.sim.result import Progress, SimResult
from tofnet.sim.scenarios import scenario


def resolve(name_or_config: str | SimConfig, *, duration: float | None = None,
            sensor_size: tuple[int, int] | None = None) -> SimConfig:
    """The config of a scenario name (or a given config) with ``duration`` and ``sensor_size`` applied."""
    if isinstance(name_or_config, SimConfig):
        config = name_or_config
        if duration is not None:
            config = config.replace(duration=duration)
    elif isinstance(name_or_config, str):
        config = scenario(name_or_config, duration)
    else:
        raise SimError(f"scenario: expected a scenario name or a SimConfig, got {type(name_or_config).__name__}")
    if sensor_size is not None:
        config = config.replace(sensor_size=sensor_size)
    return config


def simulate(name_or_config: str | SimConfig, out_dir: str | Path | None, *, duration: float | None = None,
             seed: int = 0, sensor_size: tuple[int, int] | None = None,
             progress: Progress | None = None) -> dict:
    """Simulate a scenario and write it as an ECD folder.

    Parameters
    ----------
    name_or_config : a name in ``SCENARIOS`` or a ``SimConfig``.
    out_dir : folder to write (``events.txt``, ``calib.txt``, ``groundtruth.txt``,
        ``sensor_size.txt``, ``events_depth.npy``, and ``imu.txt`` when the config has an
        IMU); ``None`` writes nothing.
    duration : seconds (default: the scenario's, 1 s).
    seed : textures, thresholds and noise; same seed, same events.
    sensor_size : ``(width, height)`` px; the intrinsics scale to keep the field of view.
    progress : ``progress(renders_done, renders_total)`` during the simulation.

    Returns
    -------
    summary dict: ``scenario``, ``seed``, ``duration_s``, ``sensor_size``, ``events``,
    ``events_on``, ``events_per_s``, ``max_angular_speed_radps`` (a bound, 0 without rotation),
    ``depth_min``/``depth_median``/``depth_max`` (m, over events), ``renders``,
    ``max_render_step_px``, ``sim_time_s``, ``write_time_s``, ``out_dir``, ``files``.
    """
    config = resolve(name_or_config, duration=duration, sensor_size=sensor_size)
    result = generate(config, seed=seed, progress=progress)
    start = time.perf_counter()
    files: list[str] = []
    if out_dir is not None:
        files = write_result(result, out_dir)
    return summarize(result, out_dir, files, write_time=time.perf_counter() - start)


def write_result(result: SimResult, out_dir: str | Path) -> list[str]:
    """Write ``result`` as an ECD folder with ``tofnet.io.ecd.write_ecd``; the file names written."""
    from tofnet.io.ecd import write_ecd  # at call time: the simulator itself needs no file formats

    write_ecd(out_dir, result.events, intrinsics=result.intrinsics, times=result.pose_times,
              positions=result.positions, quaternions=result.quaternions, sensor_size=result.sensor_size,
              gt_depth=result.gt_depth)
    files = ["events.txt", "calib.txt", "groundtruth.txt", "sensor_size.txt", "events_depth.npy"]
    if result.imu is not None:
        from tofnet.io.rotation import write_imu
        write_imu(Path(out_dir) / "imu.txt", result.imu[:, 0], result.imu[:, 1:4], result.imu[:, 4:7])
        files.append("imu.txt")
    return files


def summarize(result: SimResult, out_dir: str | Path | None = None, files: list[str] | None = None,
              write_time: float = 0.0) -> dict:
    """The summary dict ``simulate`` returns."""
    ev, depth, config = result.events, result.gt_depth, result.config
    speeds = np.linalg.norm([s.velocity for s in config.trajectory.segments], axis=1) if \
        config.trajectory.segments else np.zeros(1)
    has = depth.size > 0
    return {
        "scenario": config.name,
        "description": config.description,
        "seed": result.seed,
        "duration_s": config.duration,
        "sensor_size": tuple(config.sensor_size),
        "intrinsics": {"fx": config.intrinsics.fx, "fy": config.intrinsics.fy,
                       "cx": config.intrinsics.cx, "cy": config.intrinsics.cy},
        "max_speed_mps": float(speeds.max()),
        "max_angular_speed_radps": float(getattr(config.trajectory, "max_angular_speed", 0.0)),
        "events": int(ev.size),
        "events_on": int(np.count_nonzero(ev["p"])),
        "noise_events": result.stats["noise_events"],
        "events_per_s": ev.size / config.duration,
        "depth_min": float(depth.min()) if has else float("nan"),
        "depth_median": float(np.median(depth)) if has else float("nan"),
        "depth_max": float(depth.max()) if has else float("nan"),
        "renders": result.stats["renders"],
        "max_render_step_px": result.stats["max_render_step_px"],
        "sim_time_s": result.stats["wall_time_s"],
        "write_time_s": write_time,
        "out_dir": None if out_dir is None else str(out_dir),
        "files": list(files or []),
    }
