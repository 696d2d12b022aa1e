"""Binding a pipeline to a recording: start time, intrinsics and the velocity table."""

from __future__ import annotations

import numpy as np

from tofnet.compiler.pipeline import PipelineParams, pipeline_of
from tofnet.errors import BackendError, DataError
from tofnet.io.recording import ConstantVelocity, Intrinsics, Recording, VelocitySource


def as_pipeline(compiled) -> PipelineParams:
    """The pipeline of a ``CompiledNetwork``, a ``Network`` or a ``PipelineParams``."""
    if isinstance(compiled, PipelineParams):
        return compiled
    pipeline = getattr(compiled, "pipeline", None)
    if isinstance(pipeline, PipelineParams):
        return pipeline
    return pipeline_of(compiled)


def start_time_us(pipeline: PipelineParams, recording: Recording) -> int:
    """``t0`` in microseconds: the input process's ``t0``, else the first event's time."""
    if pipeline.t0 is not None:
        return int(round(pipeline.t0 * 1e6))
    if len(recording.events) == 0:
        return 0
    return int(recording.events["t"][0])


def intrinsics_of(pipeline: PipelineParams, recording: Recording) -> Intrinsics:
    """Intrinsics from the velocity process when given, else from the recording's calibration."""
    if pipeline.intrinsics is not None:
        fx, fy, cx, cy = pipeline.intrinsics
        return Intrinsics(fx, fy, cx, cy)
    if recording.intrinsics is None:
        raise DataError(f"{recording.source}: no camera calibration (calib.txt); the velocity process "
                        f"'{pipeline.names[3]}' needs fx, fy, cx, cy: add calib.txt or set intrinsics: [fx, fy, cx, cy]")
    return recording.intrinsics


def velocity_source_of(pipeline: PipelineParams, recording: Recording) -> VelocitySource:
    """The camera velocity the velocity process reads, per its ``source`` parameter."""
    name = pipeline.names[3]
    if pipeline.velocity_source == "constant":
        return ConstantVelocity(pipeline.velocity_constant)
    if pipeline.velocity_source == "samples":
        from tofnet.io.groundtruth import read_velocity_samples
        return read_velocity_samples(pipeline.velocity_samples)
    if recording.trajectory is None:
        raise DataError(f"{recording.source}: no ground-truth poses (groundtruth.txt), but velocity process "
                        f"'{name}' has source: groundtruth; add the poses or use source: constant/samples")
    return recording.trajectory


def velocity_table(source: VelocitySource, t0_us: int, timestep_us: int, update_every: int,
                   n_updates: int, first_update: int = 0) -> np.ndarray:
    """Camera velocity (m/s, shape ``(n_updates, 3)``) of updates ``first_update ...``.

    Update j is sent in step ``j * update_every`` and samples the velocity at that
    step's start, ``t0 + j * update_every * timestep``.
    """
    j = np.arange(first_update, first_update + n_updates, dtype=np.int64)
    t = (t0_us + j * update_every * timestep_us) * 1e-6
    table = np.ascontiguousarray(source.velocity_at(t), dtype=np.float64)
    if table.shape != (n_updates, 3):
        raise BackendError(f"velocity source returned shape {table.shape}, expected ({n_updates}, 3)")
    if not np.all(np.isfinite(table)):
        bad = t[~np.all(np.isfinite(table), axis=1)][0]
        raise DataError(f"camera velocity is not finite at t = {bad:.6f} s (check the poses or samples)")
    return table
