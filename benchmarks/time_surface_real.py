"""The time-surface estimator on real sensor recordings: where the events end, and CPU per event (run by hand).

    python benchmarks/time_surface_real.py --real FOLDER                   # behind_depth 10 and 0
    python benchmarks/time_surface_real.py --real FOLDER --velocity 0.5,0,0 --configs 'behind_depth=10;behind_depth=0'

The samples in ``--real`` (``davis346.aedat4``, ``evt2.raw``, ``evt3.raw``, ``gen4.dat``;
not distributed with tofnet; a file that is absent is skipped) come from static cameras: there is no
ground truth and the depths mean nothing, but the noise, hot pixels and bursts are a real
sensor's. Each is read with ``tofnet.io.read_recording`` and fed, as one packet, to
``TimeSurfaceEstimator`` with a constant made-up camera velocity (``--velocity`` m/s,
``constant_velocity``) and intrinsics from the sensor size (``fx = fy = 0.83 width``, the
simulated DAVIS240's 199 px at 240 px, principal point at the centre), once per
configuration of ``--configs`` (``;``-separated ``name=value`` changes of ``TimeSurfaceConfig``,
``,`` between changes of one configuration). Printed per file and configuration: the
share of events in each count (``estimator.counts``), the share that reached a fit (first
events past ``no_motion`` and ``nothing_behind``), and CPU time (``time.process_time``) per
event and per event reaching a fit, best of ``--repeat`` runs after a warm-up (numba
compilation). Markdown on stdout, progress on stderr.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import fmt, log, markdown_table  # noqa: E402
from time_surface_sweep import parse_value  # noqa: E402
from tofnet.io import read_recording  # noqa: E402
from tofnet.kernels import time_surface as ts  # noqa: E402
from tofnet.kernels.time_surface_estimator import TimeSurfaceConfig, TimeSurfaceEstimator, constant_velocity  # noqa: E402

FILES = ("davis346.aedat4", "evt2.raw", "evt3.raw", "gen4.dat")
#: The counts shown as columns (the others are zero on these files or folded into "other").
SHOWN = ("burst", "no_motion", "nothing_behind", "too_few_points", "ill_conditioned", "bad_fit", "too_near",
         "too_far", "same_step", "emitted")
FOCAL_PER_WIDTH = 199.1 / 240  # the simulated DAVIS240's fx over its width


def parse_configs(text: str) -> list[dict]:
    out = []
    for config in filter(None, (c.strip() for c in text.split(";"))):
        changes = {}
        for item in filter(None, config.split(",")):
            name, _, value = item.partition("=")
            changes[name.strip()] = parse_value(value.strip())
        out.append(changes)
    return out or [{}]


def run(events, config: TimeSurfaceConfig, velocity, repeat: int) -> tuple[dict, float]:
    """Counts of one run and the best CPU seconds of ``repeat`` runs (each on a fresh estimator)."""
    t0 = int(events["t"][0])
    TimeSurfaceEstimator(config, t0).feed(events[:1000], velocity)  # warm-up: numba compilation or cache load
    best, counts = float("inf"), None
    for _ in range(repeat):
        estimator = TimeSurfaceEstimator(config, t0)
        start = time.process_time()
        estimator.feed(events, velocity)
        best = min(best, time.process_time() - start)
        counts = estimator.counts
    return counts, best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", required=True, help="folder of the real samples (not distributed with tofnet)")
    parser.add_argument("--files", default=",".join(FILES))
    parser.add_argument("--velocity", default="0.5,0,0", help="constant camera velocity tx,ty,tz m/s")
    parser.add_argument("--configs", default="behind_depth=10;behind_depth=0",
                        help="configurations: ';' between them, ',' between one's 'name=value' changes")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    velocity_mps = tuple(float(v) for v in args.velocity.split(","))
    velocity = constant_velocity(velocity_mps)
    configs = parse_configs(args.configs)
    header = ["file", "configuration", "events", "to a fit %"] + [f"{c} %" for c in SHOWN] + \
        ["other %", "ns / event", "ns / event to a fit"]
    rows = []
    for name in filter(None, args.files.split(",")):
        path = Path(args.real) / name
        if not path.is_file():
            log(f"{name}: absent from {args.real}, skipped")
            continue
        rec = read_recording(path)
        events = rec.events
        width, height = (int(s) for s in rec.sensor_size)
        f = FOCAL_PER_WIDTH * width
        intrinsics = (f, f, (width - 1) / 2, (height - 1) / 2)
        span = (int(events["t"][-1]) - int(events["t"][0])) * 1e-6
        log(f"{name}: {len(events):,} events over {span:.2f} s, {width}x{height}, fx = fy = {f:.0f} px")
        for changes in configs:
            config = TimeSurfaceConfig((width, height), intrinsics, **changes)
            counts, cpu = run(events, config, velocity, args.repeat)
            n = len(events)
            assert sum(counts.values()) == n, counts
            first = sum(counts[c] for c in ts.COUNT_NAMES[ts.COUNT_NAMES.index("no_motion"):])
            fitted = first - counts["no_motion"] - counts["nothing_behind"]
            other = n - sum(counts[c] for c in SHOWN)
            label = ", ".join(f"{k}={v}" for k, v in changes.items()) or "defaults"
            log(f"  {label}: {100 * fitted / n:.1f} % to a fit, {100 * counts['emitted'] / n:.1f} % emitted, "
                f"{1e9 * cpu / n:.0f} ns/event")
            rows.append([name, label, fmt(n), fmt(100 * fitted / n)] + [fmt(100 * counts[c] / n) for c in SHOWN]
                        + [fmt(100 * other / n), fmt(1e9 * cpu / n), fmt(1e9 * cpu / fitted) if fitted else "-"])
    print(f"Time surface on real recordings: constant velocity {velocity_mps} m/s, fx = fy = 0.83 width, "
          f"one packet, CPU best of {args.repeat}")
    print()
    print(markdown_table(header, rows))
    print()
    print(f"reproduce: python benchmarks/time_surface_real.py --real {args.real} --velocity {args.velocity} "
          f"--configs '{args.configs}'")
    return 0


if __name__ == "__main__":
    sys.exit(main())
