"""Bands: the sensor cut into strips of whole rows that run side by side (docs/performance.md, "Workers").

A band holds rows ``[y0, y1)`` of every layer. What it needs of the camera's events is its
rows widened by the *input reach* of the network: the rows each process's declared
receptive offsets reach (``Process.receptive_offsets``, the compiler's halos), added up
along the longest path, because halos compose (a background filter of radius 1 feeding
time of travel at distance 2 needs the events of 3 rows on either side).
"""

from __future__ import annotations

import networkx as nx
import numpy as np

from tofnet.compiler.partition import receptive_offsets
from tofnet.core.network import Network

#: ``(y0, y1)``: the rows of one band, half-open.
Band = tuple[int, int]


def input_reach(network: Network) -> int:
    """Rows (px) above and below a pixel of any output from which camera events can reach it."""
    reach: dict[str, int] = {}
    for name in nx.topological_sort(network.graph):
        own = max((abs(int(dy)) for _, dy in receptive_offsets(network.process(name))), default=0)
        reach[name] = own + max((reach[p] for p in network.graph.predecessors(name)), default=0)
    return max(reach.values(), default=0)


def plan_bands(height: int, bands: int, row_load: np.ndarray | None = None) -> list[Band]:
    """``bands`` strips of consecutive rows covering ``height`` rows (fewer when there are fewer rows),
    each at least one row. ``row_load`` (events per row): cut where the cumulative load crosses
    equal shares, so busy rows make narrow bands; without it (or with no load), equal heights."""
    n = max(1, min(int(bands), int(height)))
    if row_load is None or float(np.sum(row_load)) <= 0:
        cuts = [round(k * height / n) for k in range(n + 1)]
    else:
        total = np.cumsum(np.asarray(row_load, dtype=np.float64)[:height])
        shares = total[-1] * np.arange(1, n) / n
        cuts = [0, *(int(c) + 1 for c in np.searchsorted(total, shares, "left")), height]
    for k in range(1, n):  # every band keeps at least one row, in order
        cuts[k] = min(max(cuts[k], cuts[k - 1] + 1), height - (n - k))
    return [(cuts[k], cuts[k + 1]) for k in range(n)]


def halo_rows(band: Band, reach: int, height: int) -> Band:
    """The rows whose events band ``band`` needs: its own widened by ``reach``, clipped to the sensor."""
    return max(band[0] - reach, 0), min(band[1] + reach, height)
