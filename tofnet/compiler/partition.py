"""Partitioning pixel layers into rectangular patches, one per neuromorphic core.

Every core-placed process is a layer of pixels; a core holds one rectangular patch of
it. Patches tile the sensor from (0, 0) row by row; the last column and row of patches
may be narrower (ragged). What a pixel needs on a core is declared by the process
(``Process.resources_per_pixel``); the limits come from the ``Budget``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Union

import numpy as np

from tofnet.core.process import Process
from tofnet.errors import BudgetError, quote
from tofnet.events import sensor_size_problem

#: A rectangle of pixels ``(x0, y0, x1, y1)``, half-open: columns x0..x1-1, rows y0..y1-1.
Rect = tuple[int, int, int, int]
#: What ``compile_network(patch=...)`` accepts.
PatchOption = Union[None, str, int, tuple[int, int], Mapping[str, Any]]

_SIZE = re.compile(r"^\s*(\d{1,9})\s*[xX]\s*(\d{1,9})\s*$", re.ASCII)
_SIDE = re.compile(r"^\s*\d{1,9}\s*$", re.ASCII)


def parse_patch_size(value: Any, where: str = "patch") -> tuple[int, int] | str:
    """``"auto"``, ``30`` (square), ``"30x20"`` or ``[30, 20]`` -> ``"auto"`` or ``(w, h)`` px."""
    if value is None or value == "auto":
        return "auto"
    if isinstance(value, str):
        match = _SIZE.match(value)
        if match:
            value = (int(match.group(1)), int(match.group(2)))
        elif _SIDE.match(value):
            value = int(value)
    if isinstance(value, int) and not isinstance(value, bool):
        value = (value, value)
    if (isinstance(value, (list, tuple)) and len(value) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value)):
        return (int(value[0]), int(value[1]))
    raise BudgetError(f"{where}: expected auto, a side in pixels (30), WIDTHxHEIGHT (30x30) or "
                      f"[width, height] with positive whole numbers; got {quote(value)}")


def patch_per_layer(option: PatchOption, layers: Iterable[str], where: str = "patch") -> dict[str, Any]:
    """Resolve a ``patch`` option to ``{layer: "auto" | (w, h)}`` for every core-placed layer.

    ``None`` or ``"auto"``: every layer automatic. A size: that size for every layer. A
    mapping ``{layer: size}``: per layer; layers it does not name are automatic.
    """
    layers = list(layers)
    if isinstance(option, Mapping):
        unknown = [name for name in option if name not in layers]
        if unknown:
            raise BudgetError(f"{where}.{unknown[0]}: no core-placed process of that name; "
                              f"expected one of {', '.join(layers) or '(none)'}")
        return {name: parse_patch_size(option.get(name), f"{where}.{name}") for name in layers}
    size = parse_patch_size(option, where)
    return {name: size for name in layers}


def needs_of(process: Process) -> dict[str, int]:
    """Per-pixel resource needs the process declares (zeros dropped)."""
    needs = {}
    for key, value in dict(process.resources_per_pixel).items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise BudgetError(f"{process.name} ({type(process).__name__}): resources_per_pixel[{key!r}] must be "
                              f"a whole number >= 0, got {quote(value)}")
        if value:
            needs[key] = value
    return needs


def max_pixels_per_core(process: Process, limits: Mapping[str, int], sensor_pixels: int) -> int:
    """How many pixels of ``process`` fit on one core; raises when not even one does."""
    needs = needs_of(process)
    fit = sensor_pixels
    for key, need in needs.items():
        if key not in limits:
            raise BudgetError(f"{process.name} needs {need} {key} per pixel but the budget has no per-core limit "
                              f"for {key!r}; add core: {{{key}: N}} to the budget")
        if need > limits[key]:
            raise BudgetError(f"{process.name} needs {need} {key} per pixel but a core has {limits[key]}: "
                              f"{need - limits[key]} over")
        fit = min(fit, limits[key] // need)
    return fit


def usage_of(process: Process, pixels: int) -> dict[str, int]:
    """Resources a patch of ``pixels`` pixels of ``process`` uses on its core."""
    return {key: need * pixels for key, need in needs_of(process).items()}


def check_patch(process: Process, limits: Mapping[str, int], size: tuple[int, int],
                sensor: tuple[int, int]) -> None:
    """Raise ``BudgetError`` naming the limit a fixed patch exceeds and by how much."""
    width, height = min(size[0], sensor[0]), min(size[1], sensor[1])
    fit = max_pixels_per_core(process, limits, sensor[0] * sensor[1])
    for key, used in usage_of(process, width * height).items():
        if used > limits[key]:
            side = math.isqrt(fit)
            raise BudgetError(f"{process.name}: a {size[0]}x{size[1]} patch needs {used} {key} per core "
                              f"({needs_of(process)[key]} per pixel x {width * height} pixels) but a core has "
                              f"{limits[key]}: {used - limits[key]} over; at most {fit} pixels fit "
                              f"(e.g. {side}x{side}, or patch: auto)")


def grid_of(sensor: tuple[int, int], size: tuple[int, int]) -> tuple[int, int]:
    """Patches across and down: ``(ceil(W/w), ceil(H/h))``."""
    return (-(-sensor[0] // size[0]), -(-sensor[1] // size[1]))


def auto_patch(sensor: tuple[int, int], max_pixels: int) -> tuple[int, int]:
    """The patch size that tiles ``sensor`` with the fewest cores of ``max_pixels`` pixels.

    Every width is tried with the tallest height that fits; the patch is then shrunk
    to the smallest one giving the same grid (less raggedness). Ties: the smaller
    perimeter (fewer halo pixels), then the narrower patch.
    """
    width, height = sensor
    best: tuple[tuple[int, int, int], tuple[int, int]] | None = None
    for w in range(1, width + 1):
        h = min(height, max_pixels // w)
        if h < 1:
            break
        nx, ny = grid_of(sensor, (w, h))
        size = (-(-width // nx), -(-height // ny))
        key = (nx * ny, size[0] + size[1], size[0])
        if best is None or key < best[0]:
            best = (key, size)
    if best is None:
        raise BudgetError(f"no patch of at least one pixel fits {max_pixels} pixels per core")
    return best[1]


def tile(sensor: tuple[int, int], size: tuple[int, int]) -> list[Rect]:
    """Patches of ``size`` tiling ``sensor`` from (0, 0), row by row; ragged at the far edges."""
    width, height = sensor
    w, h = min(size[0], width), min(size[1], height)
    return [(x0, y0, min(x0 + w, width), min(y0 + h, height))
            for y0 in range(0, height, h) for x0 in range(0, width, w)]


def receptive_offsets(process: Process) -> list[tuple[int, int]]:
    """Pixel offsets ``(dx, dy)`` of the input pixels a pixel of ``process`` needs (its declaration)."""
    return [tuple(o) for o in process.receptive_offsets()]


def halo_of(patch: Rect, offsets: Iterable[tuple[int, int]], sensor: tuple[int, int]) -> list[Rect]:
    """Input rectangles a core holding ``patch`` must receive, clipped to the sensor.

    Offsets along u widen the patch's rows (x intervals, rows y0..y1); offsets along v
    heighten its columns (y intervals, columns x0..x1); with ±d and a patch at least
    d wide this is the patch widened by d along u plus heightened by d along v.
    Other offsets add the shifted patch. Rectangles inside another are dropped.
    """
    x0, y0, x1, y1 = patch
    offsets = list(offsets)
    along_u = _intervals([(x0 + dx, x1 + dx) for dx, dy in offsets + [(0, 0)] if dy == 0], sensor[0])
    along_v = _intervals([(y0 + dy, y1 + dy) for dx, dy in offsets + [(0, 0)] if dx == 0], sensor[1])
    rects = [(a, y0, b, y1) for a, b in along_u] + [(x0, a, x1, b) for a, b in along_v]
    for dx, dy in offsets:
        if dx and dy:
            r = (max(x0 + dx, 0), max(y0 + dy, 0), min(x1 + dx, sensor[0]), min(y1 + dy, sensor[1]))
            if r[0] < r[2] and r[1] < r[3]:
                rects.append(r)
    rects = list(dict.fromkeys(rects))
    return [r for i, r in enumerate(rects) if not any(j != i and _inside(r, o) for j, o in enumerate(rects))]


def _intervals(spans: list[tuple[int, int]], size: int) -> list[tuple[int, int]]:
    # Clip to [0, size) and join spans that touch or overlap.
    out: list[list[int]] = []
    for a, b in sorted((max(a, 0), min(b, size)) for a, b in spans):
        if a >= b:
            continue
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def _inside(a: Rect, b: Rect) -> bool:
    return b[0] <= a[0] and b[1] <= a[1] and a[2] <= b[2] and a[3] <= b[3]


def bounding_box(rects: Iterable[Rect]) -> Rect:
    rects = list(rects)
    return (min(r[0] for r in rects), min(r[1] for r in rects), max(r[2] for r in rects), max(r[3] for r in rects))


def local_mask(rects: list[Rect]) -> tuple[Rect, np.ndarray]:
    """The union of ``rects`` as a boolean mask over their bounding box (rows = y)."""
    box = bounding_box(rects)
    mask = np.zeros((box[3] - box[1], box[2] - box[0]), dtype=bool)
    for x0, y0, x1, y1 in rects:
        mask[y0 - box[1]:y1 - box[1], x0 - box[0]:x1 - box[0]] = True
    return box, mask


def rects_mask(rects: Iterable[Rect], xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Vectorised membership: which ``(xs[i], ys[i])`` lie in any of ``rects``."""
    xs, ys = np.asarray(xs), np.asarray(ys)
    out = np.zeros(np.broadcast(xs, ys).shape, dtype=bool)
    for x0, y0, x1, y1 in rects:
        out |= (xs >= x0) & (xs < x1) & (ys >= y0) & (ys < y1)
    return out


@dataclass(frozen=True)
class LayerPlan:
    """How one core-placed process is cut into patches (before global numbering)."""

    process: Process
    patch: tuple[int, int]
    grid: tuple[int, int]
    rects: list[Rect]
    halos: list[list[Rect]]
    automatic: bool


#: Most cores one layer may be cut into (512 Loihi 2 chips); planning costs ~0.1 ms per core.
MAX_CORES_PER_LAYER = 2**16


def plan_layer(process: Process, limits: Mapping[str, int], sensor: tuple[int, int],
               request: tuple[int, int] | str) -> LayerPlan:
    """Cut ``process`` into patches: the requested size (checked) or the automatic one.

    Refuses sensors beyond ``tofnet.events.MAX_SENSOR_PIXELS`` and layers needing more
    than ``MAX_CORES_PER_LAYER`` cores before any work (so compiling never takes minutes).
    """
    problem = sensor_size_problem(*sensor)
    if problem:
        raise BudgetError(f"{process.name}: sensor size: {problem}")
    if request == "auto":
        size = auto_patch(sensor, max_pixels_per_core(process, limits, sensor[0] * sensor[1]))
    else:
        check_patch(process, limits, request, sensor)
        size = (min(request[0], sensor[0]), min(request[1], sensor[1]))
    across, down = grid_of(sensor, size)
    if across * down > MAX_CORES_PER_LAYER:
        raise BudgetError(f"{process.name}: {size[0]}x{size[1]} patches on a {sensor[0]}x{sensor[1]} sensor need "
                          f"{across * down:,} cores; at most {MAX_CORES_PER_LAYER:,} per layer are compiled "
                          "(use larger patches or patch: auto)")
    rects = tile(sensor, size)
    offsets = receptive_offsets(process)
    return LayerPlan(process, size, grid_of(sensor, size), rects,
                     [halo_of(r, offsets, sensor) for r in rects], request == "auto")


@dataclass(frozen=True)
class Traffic:
    """Spike traffic of one connection, assuming every pixel is equally likely to spike.

    ``kind == "event"``: one source spike (one event at a pixel) reaches ``mean_cores``
    destination cores on average and ``max_cores`` at most; each is one message that
    crosses cores. ``links_mean``/``links_max``: destination cores per source core
    (``None`` when the source runs on the host). ``cross_chip``: fraction of those
    messages that also cross chips. ``kind == "update"``: ``messages`` per update of a
    host source (the velocity term), ``per_second`` at its update rate.
    """

    source: str
    target: str
    kind: str
    channels: int
    mean_cores: float
    max_cores: int
    messages: float
    links_mean: float | None = None
    links_max: int | None = None
    cross_chip: float | None = None
    per_second: float | None = None
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Traffic":
        return cls(**data)


def traffic_of(network, plans: Mapping[str, tuple[LayerPlan, int]], chip_cores: int) -> list[Traffic]:
    """Traffic of every connection into a core-placed process.

    ``plans`` maps a layer name to its plan and the global index of each of its cores
    (in the plan's patch order).
    """
    out = []
    for source_port, target_port in network.connections():
        src, dst = source_port.process, target_port.process
        if dst.name not in plans:
            continue
        plan, first = plans[dst.name]
        width, height = dst.sensor_size
        names = (source_port.qualified_name, target_port.qualified_name)
        channels = source_port.spec.channels
        if source_port.spec.payload.kind == "field":
            out.append(_update_traffic(network, source_port, plan, names, channels))
            continue
        counts = np.zeros((height, width), dtype=np.int32)
        for halo in plan.halos:
            (x0, y0, x1, y1), mask = local_mask(halo)
            counts[y0:y1, x0:x1] += mask
        mean, peak = float(counts.mean()), int(counts.max())
        if src.name not in plans:
            out.append(Traffic(*names, "event", channels, mean, peak, mean,
                               note=f"{src.name} runs on the host; every delivery is a message to a core"))
            continue
        src_plan, src_first = plans[src.name]
        label = np.empty((height, width), dtype=np.int64)
        for k, (x0, y0, x1, y1) in enumerate(src_plan.rects):
            label[y0:y1, x0:x1] = k
        links = [set() for _ in src_plan.rects]
        crossing = delivered = 0
        source_chip = np.asarray(src_first) // chip_cores  # once: per core it made the loop quadratic
        for k, halo in enumerate(plan.halos):
            (x0, y0, x1, y1), mask = local_mask(halo)
            sources = label[y0:y1, x0:x1][mask]
            for s in np.unique(sources):
                links[s].add(k)
            crossing += int(np.count_nonzero(source_chip[sources] != first[k] // chip_cores))
            delivered += sources.size
        fan = [len(s) for s in links]
        out.append(Traffic(*names, "event", channels, mean, peak, mean, links_mean=float(np.mean(fan)),
                           links_max=int(max(fan)), cross_chip=crossing / max(delivered, 1),
                           note=f"a spike carries up to {channels} values (one per channel) to each core"))
    return out


def _update_traffic(network, port, plan: LayerPlan, names: tuple[str, str], channels: int) -> Traffic:
    # One message per (core, value of the field it must hold): the squares of the source's
    # field layout that overlap the core (its process declares the layout).
    width, height = plan.process.sensor_size
    side, every = port.process.field_layout(port.name)
    columns = -(-width // side)
    per_core = []
    for halo in plan.halos:
        (x0, y0, x1, y1), mask = local_mask(halo)
        ys, xs = np.nonzero(mask)
        per_core.append(len(np.unique((ys + y0) // side * columns + (xs + x0) // side)))
    messages = float(sum(per_core))
    steps = [p.timestep for p in network.processes if "timestep" in p.values]
    per_second = messages / (every * steps[0]) if steps else None
    what = f"one value per {side}x{side} patch" if side > 1 else "one value per pixel"
    return Traffic(*names, "update", channels, float(np.mean(per_core)), int(max(per_core)), messages,
                   per_second=per_second,
                   note=f"{what}, every {every} step(s); {channels} values per message")
