"""A plan's tasks: one per (recording, network, grid point), with stable ids and output folders.

A task id is readable (recording, network, parameters) and ends with a hash of what
the task computes, so editing a plan (another refractory value, another recording)
keeps the ids, and the finished outputs, of the tasks it did not change. Simulated
scenarios go to a cache folder keyed by the scenario's full configuration, the seed
and the simulator's source code.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tofnet.batch.plan import NetworkChoice, Plan, RecordingSource

#: Sub-folder of the output with one folder per task.
TASKS_DIR = "tasks"
#: The file that marks a scenario folder of the cache as complete (the simulation's summary).
SCENARIO_FILE = "scenario.json"
_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]+")


@dataclass(frozen=True)
class Task:
    """One run: a recording through a network with grid parameters (option names of ``tofnet run``).

    ``number`` is the task's position in plan order (the table's sort key) and
    ``folder`` where its outputs go; ``scenario_folder`` is the cache folder of a
    simulated recording (``None`` for files); ``fingerprint`` what its input files held.
    """

    number: int
    task_id: str
    recording: RecordingSource
    network: NetworkChoice
    params: tuple[tuple[str, Any], ...]
    backend: str | None
    keep: tuple[str, ...]
    folder: str
    scenario_folder: str | None = None
    #: Content fingerprint of the input files (``tofnet.batch.outputs.fingerprint``), set before running.
    fingerprint: str | None = None
    #: The plan's folder: errors quote fields only of files in it (``tofnet.errors.fields_shown_within``).
    plan_folder: str | None = None

    @property
    def parameters(self) -> dict[str, Any]:
        return dict(self.params)

    @property
    def recording_path(self) -> str:
        """The file or folder the task reads (a scenario's cache folder once simulated)."""
        return self.scenario_folder if self.scenario_folder is not None else str(self.recording.path)


def expand(plan: Plan) -> list[Task]:
    """Every task of ``plan``: recordings, then networks, then grid points, in plan order."""
    tasks: list[Task] = []
    points = plan.combinations()
    scenario_keys = {}
    for recording in plan.recordings:
        scenario_folder = None
        if recording.scenario is not None:
            scenario_folder = str(plan.cache / scenario_key(recording, scenario_keys))
        for network in plan.networks:
            for point in points:
                backend = network.backend or plan.backend
                task_id = make_task_id(recording, network, point, backend)
                tasks.append(Task(len(tasks), task_id, recording, network, tuple(point.items()), backend,
                                  plan.keep, str(plan.output / TASKS_DIR / task_id), scenario_folder,
                                  plan_folder=str(plan.base)))
    seen: dict[str, Task] = {}
    for task in tasks:
        if task.task_id in seen:  # only when two recordings share a name and a path; plan.py forbids it
            raise ValueError(f"tasks {seen[task.task_id].number} and {task.number} have the same id {task.task_id}")
        seen[task.task_id] = task
    return tasks


def make_task_id(recording: RecordingSource, network: NetworkChoice, point: dict[str, Any],
                 backend: str | None) -> str:
    """``RECORDING.NETWORK.key=value...-HASH``: readable, and unique by content."""
    identity = {"recording": {"label": recording.label, "duration": recording.duration, "seed": recording.seed,
                              "sensor_size": recording.sensor_size} if recording.scenario else recording.path,
                "network": network.spec, "spec_sha": _file_sha(network.spec), "backend": backend,
                "params": {k: _plain(v) for k, v in point.items()}}
    if recording.reading:  # only then: the ids of plans without reading keys stay as they were
        identity["reading"] = recording.options
    if network.estimator:  # likewise
        identity["estimator"] = network.estimator
    for switch in ("rotation", "undistort"):
        if not getattr(network, switch):  # likewise: only when turned off
            identity[switch] = False
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:10]
    readable = ".".join([recording.name, network.name, *(f"{k}={_plain(v)}" for k, v in point.items())])
    return f"{_UNSAFE.sub('_', readable)[:120]}-{digest}"


def scenario_key(recording: RecordingSource, memo: dict | None = None) -> str:
    """Cache folder name of a simulated recording: ``NAME-DURs-WxH-seedN-HASH``."""
    from tofnet.sim.run import resolve
    config = resolve(recording.scenario, duration=recording.duration, sensor_size=recording.sensor_size)
    h = hashlib.sha256()
    h.update(repr(config).encode())
    h.update(str(recording.seed).encode())
    h.update(_simulator_sha(memo).encode())  # a change to the simulator invalidates the cache
    w, hgt = config.sensor_size
    return f"{recording.scenario}-{recording.duration:g}s-{w}x{hgt}-seed{recording.seed}-{h.hexdigest()[:12]}"


def _simulator_sha(memo: dict | None) -> str:
    if memo is not None and "sim" in memo:
        return memo["sim"]
    import tofnet
    h = hashlib.sha256()
    for path in sorted((Path(tofnet.__file__).parent / "sim").glob("*.py")):
        h.update(path.read_bytes())
    if memo is not None:
        memo["sim"] = h.hexdigest()
    return h.hexdigest()


def _file_sha(path: str | None) -> str | None:
    return None if path is None else hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def _plain(value: Any) -> Any:
    """A grid value as the plan wrote it (numbers stay numbers), for ids and the table."""
    return value if isinstance(value, (int, float, str, bool)) or value is None else str(value)
