"""The mapping report: which layer went to how many cores, how full they are, and the traffic."""

from __future__ import annotations

from tofnet.compiler.compiled import CompiledNetwork, unused_limits
from tofnet.compiler.partition import Traffic


def _percent(used: int, limit: int) -> str:
    share = 100.0 * used / limit
    if used < limit:
        share = min(share, 99.9)  # never print a core that has room as 100.0% full
    return f"{used}/{limit} ({share:.1f}%)"


def _chips(chips: tuple[int, ...]) -> str:
    # Chip indices the layer occupies, e.g. "#0" or "#0-#2".
    return f"#{chips[0]}" if len(chips) == 1 else f"#{chips[0]}-#{chips[-1]}"


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def mapping_table(compiled: CompiledNetwork) -> list[str]:
    """Rows: layer, type, patch (w x h px), grid, cores, use of each per-core limit, chips."""
    resources = list(dict.fromkeys(k for layer in compiled.layers for k in layer.limits))
    header = ["layer", "type", "patch", "grid", "cores"] + [f"{r}/core" for r in resources] + ["on chip"]
    rows = []
    for layer in compiled.layers:
        patch = f"{layer.patch[0]}x{layer.patch[1]}" + (" auto" if layer.automatic else "")
        usage = [_percent(layer.usage_max[r], layer.limits[r]) if r in layer.usage_max else "-" for r in resources]
        rows.append([layer.name, layer.type, patch, f"{layer.grid[0]}x{layer.grid[1]}", str(layer.cores)]
                    + usage + [_chips(layer.chips)])
    rows.append(["total", "", "", "", str(compiled.cores_used)] + [""] * len(resources)
                + [_plural(compiled.chips_used, "chip")])
    widths = [max(len(row[i]) for row in [header] + rows) for i in range(len(header))]
    right = {4}  # numbers right-aligned

    def line(row: list[str]) -> str:
        return "  ".join(cell.rjust(w) if i in right else cell.ljust(w)
                         for i, (cell, w) in enumerate(zip(row, widths))).rstrip()

    return [line(header)] + [line(row) for row in rows]


def traffic_line(t: Traffic) -> str:
    """One connection's traffic in words."""
    if t.kind == "update":
        rate = f"; {t.per_second:,.0f} per second" if t.per_second is not None else ""
        return (f"{t.messages:,.0f} messages per update ({t.mean_cores:.2f} per core on average, "
                f"at most {t.max_cores}){rate}; {t.note}")
    text = f"{t.mean_cores:.3f} cores per spike on average, at most {t.max_cores}"
    if t.links_mean is None:
        text += f" ({100.0 * (t.mean_cores - 1):.1f}% extra messages for halos)"
    else:
        text += (f"; a source core sends to {t.links_mean:.2f} cores on average, at most {t.links_max}; "
                 f"{100.0 * (t.cross_chip or 0.0):.1f}% of messages cross chips")
    return text


def format_report(compiled: CompiledNetwork) -> str:
    """The report ``tofnet compile`` prints."""
    net, budget = compiled.network, compiled.budget
    width, height = net.sensor_size
    lines = [f"network   {net.name}, sensor {width}x{height} px",
             f"budget    {budget.describe()}", ""]
    lines += mapping_table(compiled)
    lines.append("")
    per_layer = " + ".join(str(layer.cores) for layer in compiled.layers)
    capacity = compiled.chips_used * budget.chip.cores
    share = f"{100.0 * compiled.cores_used / capacity:.1f}% of {capacity}" if capacity else "-"
    lines.append(f"cores     {per_layer} = {compiled.cores_used} on {_plural(compiled.chips_used, 'chip')} "
                 f"({share} cores)")
    if compiled.host:
        hosted = ", ".join(f"{name} ({type(net.process(name)).__name__})" for name in compiled.host)
        lines.append(f"host      {hosted}")
    notes = [(p.name, note) for p in net.processes for note in p.compiler_notes()]
    layered = [net.process(layer.name) for layer in compiled.layers]
    notes += [("budget", f"core.{name}: no process of this network needs it") for name in unused_limits(budget, layered)]
    if notes:
        lines += ["", "notes"] + [f"  {name}: {note}" for name, note in notes]
    if compiled.traffic:
        lines += ["", "traffic (every pixel equally likely to spike; each delivery to a core is one message)"]
        for t in compiled.traffic:
            lines.append(f"  {t.source} -> {t.target}")
            lines.append(f"      {traffic_line(t)}")
    return "\n".join(lines)
