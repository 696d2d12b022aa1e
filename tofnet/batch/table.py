"""The results of a batch: one row per task, as CSV (always) and Parquet (when pyarrow is there), and a plot.

Rows are sorted by task number (plan order). Every column but ``TIMING_COLUMNS`` is a
function of the plan alone, so the same plan gives the same table apart from those.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Iterable

from tofnet.eval.breakdown import BREAKDOWN_COLUMNS
from tofnet.eval.frames import CUTOFF_COLUMNS
from tofnet.io.files import atomic_path

INPUT_COLUMNS = ("task", "task_id", "recording", "recording_name", "scenario", "seed", "duration_s", "network",
                 "backend")
#: Count columns; ``dropped_<reason>`` and ``rejected_<reason>`` follow ``dropped`` and ``depth_out`` with
#: the reasons the networks' processes declare (``Process.counters``), as the rows name them, and
#: ``latency_<process.port>`` (steps, per output) follow ``latency_steps``.
COUNT_COLUMNS = ("events_in", "accepted", "dropped", "tot_spikes", "depth_out", "steps", "latency_steps")
METRIC_COLUMNS = ("matched", "coverage_pct", "mean_abs_m", "median_abs_m", "mean_rel_pct", "median_rel_pct",
                  "bias_rel_pct", *CUTOFF_COLUMNS, *BREAKDOWN_COLUMNS)
#: Columns that change from run to run of the same plan.
TIMING_COLUMNS = ("wall_time_s", "task_time_s", "cpu_time_s", "events_per_s", "worker")
OUTPUT_COLUMNS = ("depth_file", "summary_file")
#: Metrics the plot draws against each swept parameter (when any row has them).
PLOTTED = ("median_rel_pct", "mean_rel_pct", "bias_rel_pct", "coverage_pct", "depth_out")
#: Grid options that are durations (plotted in ms; a bare number is seconds, as in ``tofnet run``).
DURATIONS = ("timestep", "refractory")


def columns(parameters: Iterable[str], rows: Iterable[dict] = ()) -> list[str]:
    """The table's columns for a plan whose grid sweeps ``parameters``, with the reasons ``rows`` count."""
    keys = dict.fromkeys(key for row in rows for key in row)
    dropped = [k for k in keys if k.startswith("dropped_")]
    rejected = [k for k in keys if k.startswith("rejected_")]
    latency = [k for k in keys if k.startswith("latency_") and k not in COUNT_COLUMNS]
    counts = [*COUNT_COLUMNS[:3], *dropped, *COUNT_COLUMNS[3:5], *rejected, *COUNT_COLUMNS[5:], *latency]
    return [*INPUT_COLUMNS, *parameters, "status", "error", "notes", *counts, *METRIC_COLUMNS, *TIMING_COLUMNS,
            *OUTPUT_COLUMNS]


def sort_rows(rows: Iterable[dict]) -> list[dict]:
    return sorted(rows, key=lambda row: row["task"])


def write_table(rows: list[dict], parameters: Iterable[str], out_dir: Path, stem: str = "results") -> list[Path]:
    """Write ``results.csv`` (and ``results.parquet`` when pyarrow imports); the paths written."""
    rows = sort_rows(rows)
    names = columns(parameters, rows)
    written = [out_dir / f"{stem}.csv"]
    with atomic_path(written[0]) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for row in rows:
            writer.writerow([_csv_cell(row.get(name)) for name in names])
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    data = {name: _column([row.get(name) for row in rows]) for name in names}
    written.append(out_dir / f"{stem}.parquet")
    with atomic_path(written[-1]) as tmp:
        pq.write_table(pa.table(data), tmp)
    return written


def read_csv(path: str | Path) -> list[dict[str, str]]:
    """The rows of a ``results.csv`` as strings (empty cells are ``""``)."""
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _csv_cell(value: Any) -> Any:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return repr(value) if isinstance(value, float) else value


def _column(values: list[Any]) -> list[Any]:
    """One Parquet type per column: ints, floats, or text when the kinds mix (e.g. ``20ms`` and ``0``)."""
    present = [v for v in values if v is not None]
    if all(isinstance(v, bool) for v in present):
        return values
    if all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return values
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        return [None if v is None else float(v) for v in values]
    return [None if v is None else str(v) for v in values]


# ---------------------------------------------------------------- the plot

def numeric(value: Any, option: str) -> float | None:
    """A grid value on a numeric axis: durations in ms (``20ms`` and ``0.02`` -> 20), other numbers as they are."""
    if isinstance(value, bool) or value is None:
        return None
    if option in DURATIONS:
        from tofnet.units import seconds
        try:
            return 1e3 * seconds(value, option)
        except Exception:
            return None
    return float(value) if isinstance(value, (int, float)) else None


def plot(rows: list[dict], parameters: list[str], path: Path) -> Path | None:
    """A grid of panels: one row per metric, one column per swept parameter; a line per other setting.

    Lines join the tasks that differ only in the panel's parameter; durations sit at
    their value in ms, categorical parameters (``velocity_per``) at even spacing. ``None`` when nothing
    was swept or no task succeeded.
    """
    swept = [p for p in parameters if len({repr(r.get(p)) for r in rows}) > 1]
    ok = [r for r in sort_rows(rows) if r.get("status") == "ok"]
    metrics = [m for m in PLOTTED if any(_finite(r.get(m)) for r in ok)]
    if not swept or not ok or not metrics:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(metrics), len(swept), figsize=(4.2 * len(swept), 2.6 * len(metrics)),
                             squeeze=False, constrained_layout=True)
    for j, option in enumerate(swept):
        values = []
        for r in ok:
            if repr(r[option]) not in map(repr, values):
                values.append(r[option])
        positions = [numeric(v, option) for v in values]
        if any(p is None for p in positions):
            positions = list(range(len(values)))
        where = {repr(v): p for v, p in zip(values, positions)}
        # one line per recording, network and value of the other swept parameters
        distinct = [p for p in ("network", *swept) if p != option and len({repr(r.get(p)) for r in ok}) > 1]
        groups: dict[str, list[dict]] = {}
        for r in ok:
            label = " ".join([r["recording_name"], *(f"{p}={r.get(p)}" for p in distinct)])
            groups.setdefault(label, []).append(r)
        for i, metric in enumerate(metrics):
            ax = axes[i][j]
            for label, members in groups.items():
                members = sorted(members, key=lambda r: where[repr(r[option])])
                ax.plot([where[repr(r[option])] for r in members], [_value(r.get(metric)) for r in members],
                        marker="o", ms=3, lw=1, label=label)
            ax.set_xticks(positions, [str(v) for v in values])  # the values as the plan wrote them
            ax.set_xlabel(option)
            ax.set_ylabel(metric)
            ax.grid(alpha=0.3)
            if i == 0 and len(groups) <= 12:
                ax.legend(fontsize=6)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _value(value: Any) -> float:
    return float(value) if _finite(value) else math.nan
