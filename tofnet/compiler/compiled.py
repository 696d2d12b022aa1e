"""The compiled network: a network, its budget and where every pixel of every layer runs."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from tofnet.compiler.budget import CORE_LIMITS, LOIHI2, Budget
from tofnet.compiler.partition import (PatchOption, Rect, Traffic, auto_patch, max_pixels_per_core,
                                       needs_of, patch_per_layer, plan_layer, rects_mask, traffic_of, usage_of)
from tofnet.core.network import Network
from tofnet.errors import BackendError, BudgetError

PLACEMENTS = ("core", "host")


@dataclass(frozen=True)
class CoreAssignment:
    """One neuromorphic core: the patch of one layer it holds and the input it receives.

    ``index`` is global (cores numbered chip by chip); ``chip`` and ``slot`` (core within
    the chip) locate it. Pixels ``x0 <= x < x1``, ``y0 <= y < y1``. ``usage`` is what the
    patch uses of each per-core limit. ``halo`` lists the input pixel rectangles
    (half-open ``(x0, y0, x1, y1)``) whose spikes the core must receive.
    """

    index: int
    chip: int
    slot: int
    process: str
    x0: int
    y0: int
    x1: int
    y1: int
    usage: dict[str, int]
    halo: tuple[Rect, ...]

    @property
    def rect(self) -> Rect:
        return (self.x0, self.y0, self.x1, self.y1)

    @property
    def pixels(self) -> int:
        return (self.x1 - self.x0) * (self.y1 - self.y0)

    def holds(self, x: int, y: int) -> bool:
        """Whether pixel ``(x, y)`` of this layer lives on this core."""
        return self.x0 <= x < self.x1 and self.y0 <= y < self.y1

    def receives(self, x: int, y: int) -> bool:
        """Whether an input spike at pixel ``(x, y)`` must reach this core."""
        return any(x0 <= x < x1 and y0 <= y < y1 for x0, y0, x1, y1 in self.halo)

    def receives_mask(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Vectorised ``receives``: a boolean array shaped like ``xs``/``ys``."""
        return rects_mask(self.halo, xs, ys)

    def to_dict(self) -> dict[str, Any]:
        return {"index": self.index, "chip": self.chip, "slot": self.slot, "process": self.process,
                "x0": self.x0, "y0": self.y0, "x1": self.x1, "y1": self.y1, "usage": dict(self.usage),
                "halo": [list(r) for r in self.halo]}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "CoreAssignment":
        return cls(**{**data, "usage": dict(data["usage"]), "halo": tuple(tuple(r) for r in data["halo"])})


@dataclass(frozen=True)
class LayerMapping:
    """One core-placed process: patch size (w, h) px, grid of patches, its cores and their use.

    ``first_core`` is the lowest global index of its cores (contiguous on one chip; on
    several chips the layers of a region are numbered together, see ``core_numbers``).

    ``usage_max`` is the use of the fullest core (ragged edge cores use less);
    ``limits`` the per-core limits it was checked against; ``chips`` the chips it spans.
    """

    name: str
    type: str
    patch: tuple[int, int]
    grid: tuple[int, int]
    cores: int
    first_core: int
    per_pixel: dict[str, int]
    usage_max: dict[str, int]
    limits: dict[str, int]
    chips: tuple[int, ...]
    automatic: bool

    def to_dict(self) -> dict[str, Any]:
        out = dict(self.__dict__)
        out.update(patch=list(self.patch), grid=list(self.grid), chips=list(self.chips))
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "LayerMapping":
        return cls(**{**data, "patch": tuple(data["patch"]), "grid": tuple(data["grid"]),
                      "chips": tuple(data["chips"])})


@dataclass(frozen=True, eq=False)
class CompiledNetwork:
    """A network placed on cores under a budget; what backends run.

    ``layers`` in topological order, ``cores`` by global index, ``traffic`` per
    connection into a core-placed layer, ``host`` the processes that run off-chip.
    """

    network: Network
    budget: Budget
    layers: tuple[LayerMapping, ...]
    cores: tuple[CoreAssignment, ...]
    traffic: tuple[Traffic, ...]
    host: tuple[str, ...]
    patch: Any = None
    _maps: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def cores_used(self) -> int:
        return len(self.cores)

    @property
    def chips_used(self) -> int:
        return -(-self.cores_used // self.budget.chip.cores)

    def layer(self, name: str) -> LayerMapping:
        for layer in self.layers:
            if layer.name == name:
                return layer
        raise BudgetError(f"no core-placed layer {name!r}; layers: {', '.join(l.name for l in self.layers)}")

    def cores_of(self, name: str) -> list[CoreAssignment]:
        """The cores of layer ``name``, in patch order (row by row)."""
        self.layer(name)  # raises for an unknown layer
        return sorted((c for c in self.cores if c.process == name), key=lambda c: (c.y0, c.x0))

    def core_map(self, name: str) -> np.ndarray:
        """``(height, width)`` array: the global index of the core holding each pixel of ``name``."""
        if ("core", name) not in self._maps:
            width, height = self.network.process(name).sensor_size
            out = np.empty((height, width), dtype=np.int32)
            for core in self.cores_of(name):
                out[core.y0:core.y1, core.x0:core.x1] = core.index
            self._maps[("core", name)] = out
        return self._maps[("core", name)]

    def fanout_map(self, name: str) -> np.ndarray:
        """``(height, width)`` array: how many cores of ``name`` an input spike at each pixel reaches."""
        if ("fanout", name) not in self._maps:
            width, height = self.network.process(name).sensor_size
            out = np.zeros((height, width), dtype=np.int32)
            ys, xs = np.mgrid[0:height, 0:width]
            for core in self.cores_of(name):
                out += core.receives_mask(xs, ys)
            self._maps[("fanout", name)] = out
        return self._maps[("fanout", name)]

    def cores_receiving(self, name: str, x: int, y: int) -> list[int]:
        """Global indices of the cores of layer ``name`` an input spike at ``(x, y)`` must reach."""
        return [core.index for core in self.cores_of(name) if core.receives(x, y)]

    def summary(self) -> dict[str, Any]:
        """Plain-data totals (for the CLI and JSON)."""
        return {"network": self.network.name, "sensor_size": list(self.network.sensor_size),
                "budget": self.budget.name, "cores_used": self.cores_used, "chips_used": self.chips_used,
                "cores_per_layer": {l.name: l.cores for l in self.layers}}


def network_of(compiled) -> Network:
    """The network of a ``CompiledNetwork``, or a ``Network`` itself."""
    if isinstance(compiled, CompiledNetwork):
        return compiled.network
    if isinstance(compiled, Network):
        return compiled
    raise BackendError(f"expected a CompiledNetwork or a Network, got {type(compiled).__name__}")


def compile_network(network: Network, budget: Budget | str | Mapping = LOIHI2,
                    patch: PatchOption = None) -> CompiledNetwork:
    """Place ``network`` on neuromorphic cores under ``budget``.

    Parameters
    ----------
    network
        A validated ``Network``; processes with ``placement == "core"`` are cut into patches.
    budget
        A ``Budget``, a built-in budget name or a budget mapping.
    patch
        ``None`` or ``"auto"`` (fewest cores), ``(w, h)`` px for every layer, or
        ``{process_name: (w, h) | "auto"}``.

    Raises
    ------
    BudgetError
        When a pixel, a fixed patch or the whole network does not fit, saying what is
        over and by how much.
    """
    budget = budget if isinstance(budget, Budget) else Budget.from_dict(budget)
    ordered = network.topological_order()
    for process in ordered:
        if process.placement not in PLACEMENTS:
            raise BudgetError(f"{process.name} ({type(process).__name__}): placement must be 'core' or 'host', "
                              f"got {process.placement!r}")
    layered = [p for p in ordered if p.placement == "core"]
    requests = patch_per_layer(patch, [p.name for p in layered])
    limits = budget.core.limits()
    _check_limit_names(network, budget, layered)
    plans = [plan_layer(p, limits, p.sensor_size, requests[p.name]) for p in layered]
    total = sum(len(plan.rects) for plan in plans)
    _check_chips(network, budget, plans, total)

    per_chip = budget.chip.cores
    numbers = core_numbers(plans, per_chip)
    layers, cores, by_name = [], [], {}
    for plan, indices in zip(plans, numbers):
        process = plan.process
        by_name[process.name] = (plan, indices)
        for index, rect, halo in zip(indices, plan.rects, plan.halos):
            pixels = (rect[2] - rect[0]) * (rect[3] - rect[1])
            cores.append(CoreAssignment(index, index // per_chip, index % per_chip, process.name, *rect,
                                        usage=usage_of(process, pixels), halo=tuple(halo)))
        full = usage_of(process, plan.patch[0] * plan.patch[1])
        chips = tuple(sorted({i // per_chip for i in indices}))
        layers.append(LayerMapping(process.name, type(process).__name__, plan.patch, plan.grid, len(plan.rects),
                                   min(indices), usage_of(process, 1), full, {k: limits[k] for k in full}, chips,
                                   plan.automatic))
    cores.sort(key=lambda c: c.index)
    host = tuple(p.name for p in ordered if p.placement == "host")
    traffic = traffic_of(network, by_name, per_chip)
    return CompiledNetwork(network, budget, tuple(layers), tuple(cores), tuple(traffic), host, patch)


def unused_limits(budget: Budget, layered: list) -> list[str]:
    """The budget's own per-core limits (``extra``) that no core-placed process of ``layered`` needs."""
    needed = {key for process in layered for key in needs_of(process)}
    return [name for name, _ in budget.core.extra if name not in needed]


def _check_limit_names(network: Network, budget: Budget, layered: list) -> None:
    """A limit no process needs, spelt like one that is (``acumulators``), would leave the real one at its
    default unseen: one line. Others are the user's (a budget kept for several networks): the report says so."""
    import difflib

    known = sorted({*CORE_LIMITS, *(key for process in layered for key in needs_of(process))})
    for name in unused_limits(budget, layered):
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
        if close:
            stays = budget.core.limits().get(close[0])
            raise BudgetError(f"budget.core.{name}: no process of network {network.name!r} needs {name!r}; did you "
                              f"mean {close[0]!r}?" + (f" (its limit stays {stays})" if stays is not None else ""))


def core_numbers(plans: list, per_chip: int) -> list[list[int]]:
    """Global core index of every patch of every layer (lists in each plan's patch order).

    On one chip, layer after layer. When the network needs several chips, the layers of
    one image region are numbered together, region by region (regions: the patches of the
    layer with the largest patches, row by row), so a region's layers share a chip where
    they fit and spikes between layers rarely cross chips.
    """
    total = sum(len(plan.rects) for plan in plans)
    if total <= per_chip or len(plans) < 2:
        out, index = [], 0
        for plan in plans:
            out.append(list(range(index, index + len(plan.rects))))
            index += len(plan.rects)
        return out
    anchor = max(plans, key=lambda plan: plan.patch[0] * plan.patch[1])
    (aw, ah), columns = anchor.patch, anchor.grid[0]
    keyed = []
    for layer, plan in enumerate(plans):
        for k, (x0, y0, x1, y1) in enumerate(plan.rects):
            cx, cy = (x0 + x1 - 1) // 2, (y0 + y1 - 1) // 2  # the region holding the patch's centre
            keyed.append(((cy // ah) * columns + cx // aw, layer, k))
    out = [[0] * len(plan.rects) for plan in plans]
    for index, (_, layer, k) in enumerate(sorted(keyed)):
        out[layer][k] = index
    return out


def _check_chips(network: Network, budget: Budget, plans: list, total: int) -> None:
    if budget.max_cores is None or total <= budget.max_cores:
        return
    per_chip = budget.chip.cores
    needed = -(-total // per_chip)
    breakdown = " + ".join(f"{len(p.rects)} {p.process.name}" for p in plans)
    message = (f"network {network.name!r} needs {total} cores ({breakdown}) on {budget.max_chips} chip(s) of "
               f"{per_chip} cores: {total - budget.max_cores} over; allow max_chips: {needed}")
    if not all(p.automatic for p in plans):
        limits = budget.core.limits()
        auto = 0
        for p in plans:
            sensor = p.process.sensor_size
            size = auto_patch(sensor, max_pixels_per_core(p.process, limits, sensor[0] * sensor[1]))
            auto += -(-sensor[0] // size[0]) * -(-sensor[1] // size[1])
        if auto < total:
            message += f" (patch: auto needs {auto} cores)"
    raise BudgetError(message)
