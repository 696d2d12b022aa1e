"""The closing report of ``tofnet run`` (and the lines ``tofnet live`` shares with it): where every
event went, what each process counted, how the work was split, and how fast."""

from __future__ import annotations

from tofnet.units import format_steps


def workers_line(workers: dict) -> str:
    """How a run was split: ``64 bands of rows on 2 threads; run whole: velocity`` (multiproc: processes)."""
    whole = f"; run whole: {', '.join(workers['whole'])}" if workers["whole"] else ""
    bands, count = workers["bands"], workers["threads"]
    unit = {"threads": ("thread", "threads"), "processes": ("process", "processes")}[workers.get("unit", "threads")]
    why = f"; one band: {workers['one_band']}" if workers.get("one_band") else ""
    return f"{bands} band{'s' if bands != 1 else ''} of rows on {count} {unit[count != 1]}{whole}{why}"


def compile_line(seconds: float, count: int) -> str:
    """The summary's line on kernels compiled during the command (first run only: numba caches them)."""
    from tofnet.kernels.compilation import kernels
    return (f"compile        {seconds:.3f} s  {kernels(count)} compiled, not counted in the network's time "
            "(first run only: numba caches them; 'tofnet warmup' does it ahead)")


def undistortion_line(undistortion: dict) -> str:
    """The summary's line on the lens."""
    lens = f"{undistortion['model']} {' '.join(f'{c:.4g}' for c in undistortion['coefficients'])}"
    if not undistortion["ran"]:
        return f"off ({undistortion['why']}): a pinhole, although the recording's lens has {lens} distortion"
    if "velocity" in undistortion:
        return f"{lens}: A t through the lens ({undistortion['velocity']}), raw pixels"
    counts = undistortion["counts"]
    return (f"{lens}: spikes moved to undistorted pixels ({undistortion['process']}): passed "
            f"{counts.get('passed', 0):,}, left image {counts.get('left_image', 0):,}, merged {counts.get('merged', 0):,}")


def reader_lines(summary: dict) -> list[str]:
    """Where every event went, once per process that reads the events (``RunResult.readers``)."""
    readers = summary.get("readers") or {"": {"events_in": summary["events_in"], "accepted": summary["accepted"],
                                              "dropped": summary["dropped"]}}
    lines = []
    for name, account in readers.items():
        lines.append(f"events in      {account['events_in']:>12,}" + (f"  read by {name}" if len(readers) > 1 else ""))
        lines.append(f"  accepted     {account['accepted']:>12,}")
        lines += [f"  dropped      {count:>12,}  {reason.replace('_', ' ')}"
                  for reason, count in account["dropped"].items()]
    return lines


def latency_lines(summary: dict) -> list[str]:
    """The steps from an event to each output (one line when there is one output)."""
    ms = summary["timestep_s"] * 1e3
    latency = summary.get("latency") or {}
    if len(set(latency.values())) <= 1:
        return [f"latency        {format_steps(summary['latency_steps'])} ({summary['latency_s'] * 1e3:g} ms)"]
    return [f"latency        {format_steps(steps)} ({steps * ms:g} ms)  {name}" for name, steps in latency.items()]


def process_lines(summary: dict, result, skip=frozenset(), totals_said: bool = False) -> list[str]:
    """A line of counts per process that counted something, but for the processes in ``skip``, a
    reader's account of the events (said above) and, when ``totals_said``, the counts that go into
    a total (said as the total)."""
    readers = summary.get("readers", {})
    lines = []
    for process, counts in summary["counts"].items():
        if process in skip:
            continue
        declared = result.declared.get(process, {})
        told = [f"{k.replace('_', ' ')} {v:,}" for k, v in counts.items()
                if not (totals_said and declared.get(k, {}).get("total"))
                and not (process in readers and declared.get(k, {}).get("kind") in ("read", "accepted", "dropped"))]
        if told:
            lines.append(f"{process:<14} {', '.join(told)}")
    return lines


def format_summary(summary: dict, result, written: dict, network_width) -> str:
    """The closing report: where every event went, what each process did, and how fast."""
    width, height = network_width
    lines = [f"recording      {summary['recording']}  ({width}x{height} px, {summary['steps']} steps of "
             f"{summary['timestep_s'] * 1e3:g} ms)",
             f"backend        {summary['backend']}",
             *([f"workers        {workers_line(summary['workers'])}"] if summary.get("workers") else []),
             *([f"rotation       {summary['rotation']}"] if summary.get("rotation") else []),
             *([f"undistort      {undistortion_line(summary['undistortion'])}"] if summary.get("undistortion") else []),
             *reader_lines(summary)]
    depth_names = result.depth_outputs
    if len(depth_names) == 1:
        lines += [f"{total.replace('_', ' '):<14} {count:>12,}" for total, count in result.totals().items()]
        # the other processes' counts (a denoiser's drops, a user's gate), the totals' and the depth's said apart
        lens = (summary.get("undistortion") or {}).get("process")  # its counts are on the undistort line
        lines += process_lines(summary, result, skip={depth_names[0].partition(".")[0], lens}, totals_said=True)
        lines.append(f"depth out      {summary['depth_out']:>12,}  -> {written[depth_names[0]]}")
        # Every declared reason, zeros too: a zero says the check ran and rejected nothing.
        lines += [f"  rejected     {count:>12,}  {reason.replace('_', ' ')}"
                  for reason, count in summary["rejected"].items()]
    else:
        lines += process_lines(summary, result)
    for name, path in written.items():
        if name.startswith("monitor "):
            lines.append(f"monitor        {name[8:]} -> {path}")
        elif len(depth_names) != 1 or name != depth_names[0]:
            lines.append(f"output         {len(result.outputs[name]):>12,}  {name} -> {path}")
    for name in depth_names:
        z = result.outputs[name]["z"]
        if len(z):
            import numpy as np
            which = "" if len(depth_names) == 1 else f" ({name})"
            lines.append(f"depth range    {np.percentile(z, 5):.3f} .. {np.percentile(z, 95):.3f} m (5th-95th pct), "
                         f"median {np.median(z):.3f} m{which}")
    # A network time below the clock's resolution gives no rate worth printing (not "inf").
    rate = (f"{summary['events_in'] / summary['wall_time_s'] / 1e6:.2f} M events/s"
            if summary["wall_time_s"] >= 1e-4 else "too short to give a rate")
    lines += latency_lines(summary)
    setup = summary.get("setup_time_s", 0.0)  # the network built, the kernels' state, worker processes started
    read = summary.get("read_time_s", 0.0)  # the file opened and loaded, and decoded between packets
    kernels = summary.get("compile_time_s", 0.0)  # compiled, or loaded from numba's cache
    lines.append(f"wall time      {summary['wall_time_s']:.3f} s network ({rate}), "
                 + (f"{read:.3f} s reading, " if read >= 5e-4 else "")
                 + (f"{setup:.3f} s set-up, " if setup >= 5e-4 else "")
                 + (f"{kernels:.3f} s kernels, " if kernels >= 5e-4 else "") + f"{summary['total_time_s']:.3f} s in all")
    if summary.get("kernels_compiled"):
        lines.append(compile_line(summary["compile_time_s"], summary["kernels_compiled"]))
    return "\n".join(lines + warning_lines(summary, result, network_width))


def warning_lines(summary: dict, result, network_width) -> list[str]:
    """A line per drop a reader declares a warning for (``Count.warning``: events outside the sensor,
    pointing to --sensor-size), ``tofnet run``'s and ``tofnet live``'s."""
    width, height = network_width
    lines = []
    for reader, account in list(summary.get("readers", {}).items())[:1]:  # every reader sees the same events
        for reason, count in account["dropped"].items():
            warning = result.declared.get(reader, {}).get(reason, {}).get("warning")
            if count and warning:
                if reason == "out_of_bounds" and summary.get("stated_sensor_size"):  # a crop the notes explain
                    warning = "events lay outside the {width}x{height} sensor (a crop of the file's, see the note)"
                lines.append(f"warning        {count:,} {warning.format(width=width, height=height)}")
    return lines
