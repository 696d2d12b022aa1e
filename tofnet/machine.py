"""The machine tofnet runs on, as a worker count needs it."""

from __future__ import annotations

import os


def cpu_count() -> int:
    """CPUs this process may use: its affinity mask where the system has one (a container's or a Slurm
    job's CPU set, ``taskset``), not every CPU of the host, which ``os.cpu_count()`` counts."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)
