"""Core-placed processes of a compiled network run in worker processes: planning and the host's stand-in.

Each core-placed process has one model instance per compiled core (``Region`` = the
core's pixels), held by a worker. The host's ``RemoteModel`` takes the process's place
in the ``GraphExecutor``: it sends each core exactly the input records the compiled
mapping routes to it (spikes inside the core's halo; field updates to every core), and
joins what the cores send back. A model that cannot hold a region runs as one instance.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from tofnet.backends.band_merge import merged_by_step
from tofnet.compiler.partition import rects_mask
from tofnet.core.process import Process
from tofnet.kernels.region import Region
from tofnet.models.base import Model, ModelContext, splits_into_regions

#: A model instance on a worker: (process name, core index; -1 for a whole-layer instance).
Key = tuple[str, int]


@dataclass(frozen=True)
class WorkerPlan:
    """The compiled cores (global indices) one worker runs."""

    index: int
    cores: tuple[int, ...]


def plan_workers(compiled, workers: int, row_load: np.ndarray | None = None) -> list[WorkerPlan]:
    """Split every core-placed layer's cores over at most ``workers`` processes.

    Each layer's cores (in patch order, row by row) are dealt out in contiguous groups, so every
    worker holds a share of every layer and its halos stay between neighbours. Without
    ``row_load`` (events per sensor row) the groups have equal numbers of cores; with it, they
    are cut between rows of patches where the cumulative load comes nearest equal shares (a
    worker's band of rows is its cores' rows: ``shared_bands.band_rows``). Workers that would
    get nothing are not planned.
    """
    n = max(1, min(int(workers), max((layer.cores for layer in compiled.layers), default=1)))
    cores: list[list[int]] = [[] for _ in range(n)]
    for layer in compiled.layers:
        layer_cores = compiled.cores_of(layer.name)
        indices = np.array([core.index for core in layer_cores], dtype=np.int64)
        cuts = _load_cuts(layer_cores, n, row_load)
        groups = np.split(indices, cuts) if cuts is not None else np.array_split(indices, n)
        for w, group in enumerate(groups):
            cores[w].extend(int(i) for i in group)
    return [WorkerPlan(w, tuple(c)) for w, c in enumerate(cores)]


def _load_cuts(layer_cores, n: int, row_load: np.ndarray | None) -> list[int] | None:
    """Where to cut ``layer_cores`` (patch order) into ``n`` groups balanced by ``row_load``: only
    where a row of patches starts, each group non-empty; None (equal groups) without a load or
    with fewer rows of patches than groups."""
    if n < 2 or row_load is None or float(np.sum(row_load)) <= 0:
        return None
    starts = [i for i in range(1, len(layer_cores)) if layer_cores[i].y0 != layer_cores[i - 1].y0]
    if len(starts) < n - 1:
        return None
    load = np.concatenate([[0.0], np.cumsum(np.asarray(row_load, dtype=np.float64))])
    last = len(load) - 1

    def before(i: int) -> float:  # the load of the rows above core i's row of patches
        return load[min(layer_cores[i].y0, last)]

    total, cuts, j = load[-1], [], -1
    for k in range(1, n):  # the start nearest the k-th share, after the previous cut, leaving one per later cut
        j = min(range(j + 1, len(starts) - (n - 1 - k)), key=lambda i: abs(before(starts[i]) - total * k / n))
        cuts.append(starts[j])
    return cuts


def routing_table(compiled, plans: list[WorkerPlan], layer: str) -> np.ndarray:
    """``(workers, height, width)`` booleans: which workers a spike at each pixel reaches, for ``layer``."""
    width, height = compiled.network.process(layer).sensor_size
    ys, xs = np.mgrid[0:height, 0:width]
    route = np.zeros((len(plans), height, width), dtype=bool)
    for core in compiled.cores_of(layer):
        worker = next(p.index for p in plans if core.index in p.cores)
        route[worker] |= core.receives_mask(xs, ys)
    return route


@dataclass(frozen=True)
class ModelSpec:
    """What a worker needs to build one model instance (plain, picklable data)."""

    key: Key
    model_class: type
    process_class: type
    process_name: str
    values: dict
    ctx: ModelContext

    def build(self) -> Model:
        process = self.process_class(name=self.process_name, **self.values)
        return self.model_class(process, self.ctx)


@dataclass(frozen=True)
class Placement:
    """One instance of a remote process: its key, worker, and the input rectangles it needs."""

    key: Key
    worker: int
    halo: tuple | None  # None: every record
    rect: tuple[int, int, int, int] | None = None  # (x0, y0, x1, y1) held; None: the whole sensor


class RemoteModel:
    """The host's stand-in for a core-placed process whose instances live on workers.

    ``call(worker, message, reply_kind, doing)`` sends and waits (the session's channels);
    the instances run in parallel on their workers, one round trip per ``run``.
    """

    def __init__(self, process: Process, model_class: type, placements: list[Placement],
                 exchange: Callable[[dict[int, tuple]], dict[int, tuple]]):
        self.process = process
        self.model_class = model_class
        self.placements = placements
        self.exchange = exchange
        self._spike_ports = {spec.name for spec in process.inports if spec.payload.kind == "spikes"}
        self._dtypes = {spec.name: spec.payload.dtype for spec in process.outports}

    def _route(self, placement: Placement, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        if placement.halo is None:
            return inputs
        out = {}
        for port, records in inputs.items():
            if port in self._spike_ports and len(records):
                records = records[rects_mask(placement.halo, records["x"], records["y"])]
            out[port] = records
        return out

    def run(self, first: int, end: int, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        jobs: dict[int, list] = {}
        for placement in self.placements:
            jobs.setdefault(placement.worker, []).append((placement.key, self._route(placement, inputs)))
        replies = self.exchange({w: ("run", items, first, end) for w, items in jobs.items()})
        parts: dict[str, list[np.ndarray]] = {port: [] for port in self._dtypes}
        for worker in sorted(replies):
            for _, outputs in replies[worker][1]:
                for port, records in outputs.items():
                    if len(records):
                        parts[port].append(records)
        # each instance's records are sorted by step: merged by step (bands of rows from the top: the canonical
        # order; other placements' steps are then re-sorted within, linearly), not joined, which left the
        # executor a sort of the whole output (0.4 s of a 1 s run)
        return {port: merged_by_step(chunks, self._dtypes[port]) for port, chunks in parts.items()}

    def _each(self, kind: str, *args) -> list:
        """Send ``(kind, keys, *args)`` to every worker holding an instance; the answers in placement order."""
        workers = sorted({p.worker for p in self.placements})
        replies = self.exchange({w: (kind, [p.key for p in self.placements if p.worker == w], *args)
                                 for w in workers})
        by_key = {}
        for w in workers:
            keys = [p.key for p in self.placements if p.worker == w]
            by_key.update(zip(keys, replies[w][1]))
        return [by_key[p.key] for p in self.placements]

    def get_var(self, name: str, step: int) -> np.ndarray:
        parts = self._each("get", name, step)
        if len(parts) == 1 and self.placements[0].rect is None:
            return parts[0]
        width, height = self.process.sensor_size
        first = np.asarray(parts[0])
        full = np.zeros(first.shape[:-2] + (height, width), dtype=first.dtype)
        for placement, part in zip(self.placements, parts):
            x0, y0, x1, y1 = placement.rect
            full[..., y0:y1, x0:x1] = part
        return full

    def set_var(self, name: str, value: np.ndarray, step: int) -> None:
        self._each("set", name, value, step)

    def set_param(self, name: str, value) -> None:
        self._each("param", name, value)

    def counts(self) -> dict[str, int]:
        workers = sorted({p.worker for p in self.placements})
        keys = [p.key for p in self.placements]
        replies = self.exchange({w: ("counts", [k for p, k in zip(self.placements, keys) if p.worker == w])
                                 for w in workers})
        return summed_counts(counts for worker in workers for counts in replies[worker][1])


def summed_counts(parts) -> dict[str, int]:
    """The counts of a process's instances (bands, cores), name by name: the process's own."""
    total: dict[str, int] = {}
    for counts in parts:
        for name, value in counts.items():
            total[name] = total.get(name, 0) + int(value)
    return total


def placements_for(compiled, process: Process, model_class: type, plans: list[WorkerPlan],
                   ctx: ModelContext) -> tuple[list[Placement], list[ModelSpec]]:
    """Where the instances of ``process`` run and how each is built."""
    values = process.values
    ctx = replace(ctx, recording=None)  # what a core-placed model needs arrives on its ports
    if not splits_into_regions(process, model_class):
        worker = sorted(plans, key=lambda p: len(p.cores))[0].index
        key = (process.name, -1)
        return [Placement(key, worker, None)], [ModelSpec(key, model_class, type(process), process.name, values, ctx)]
    placements, specs = [], []
    for core in compiled.cores_of(process.name):
        worker = next(p.index for p in plans if core.index in p.cores)
        key = (process.name, core.index)
        region = Region(core.x0, core.x1, core.y0, core.y1)
        placements.append(Placement(key, worker, tuple(core.halo), core.rect))
        specs.append(ModelSpec(key, model_class, type(process), process.name, values, replace(ctx, region=region)))
    return placements, specs

