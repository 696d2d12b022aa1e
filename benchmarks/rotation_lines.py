"""The time surface under a constant rotation, by the direction of its image motion (by hand, not in CI).

    python benchmarks/rotation_lines.py                          # travel coordinates (the default)
    python benchmarks/rotation_lines.py --set coordinates=time   # eq. 7 on the fitted gradient instead

A textured wall 2 m away, no background activity, no threshold mismatch, 0.5 s; the camera
slides at 0.5 m/s along x and turns at a constant rate whose image motion at the centre is
``share`` times the slide's (yaw: along the image motion ``f``; pitch: across it; roll: around the
centre). Every scene is simulated (cached like ``accuracy.py``, seed 0) and run through the
time-surface estimator with ω from the exact trajectory, so what is left is the estimator's own
error: docs/time_surface.md, section 7h (where a rotation across ``f`` used to double the error).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import default_cache, fmt, log, print_tables, recording_for, run_improved  # noqa: E402
from motion_sweep import parse_settings  # noqa: E402

from tofnet.sim.camera import DEFAULT_INTRINSICS, constant  # noqa: E402
from tofnet.sim.config import SimConfig  # noqa: E402
from tofnet.sim.rotation import RotatingTrajectory, Sway  # noqa: E402
from tofnet.sim.scene import Scene  # noqa: E402
from tofnet.sim.texture import Texture  # noqa: E402

DEPTH, SPEED, DURATION = 2.0, 0.5, 0.5  # m, m/s, s
#: (label, axis, rate as a multiple of the slide's image motion at the centre): yaw turns the image along the
#: slide's (positive: with it), pitch across it, roll around the centre.
CASES = (("none", None, 0.0), ("yaw x1", "yaw", 1.0), ("yaw x3", "yaw", 3.0), ("yaw x-0.5", "yaw", -0.5),
         ("pitch x1", "pitch", 1.0), ("roll x1", "roll", 1.0))


def case_config(label: str, axis: str | None, share: float) -> SimConfig:
    """The scene of one case (``share`` times ``SPEED / DEPTH`` rad/s about ``axis``)."""
    scene = Scene(objects=(), background_depth=DEPTH,
                  background=Texture("shapes", scale=12 * DEPTH / DEFAULT_INTRINSICS.fx))
    trajectory = constant((SPEED, 0.0, 0.0), DURATION)
    if axis is not None:
        rate = share * SPEED / DEPTH
        sways = {axis: Sway(offset=-0.5 * rate * DURATION, rate=rate)}
        trajectory = RotatingTrajectory(trajectory, **sways)
    name = "rotation_lines_" + label.replace(" ", "_")
    return SimConfig(name, scene, trajectory, DURATION, contrast_sigma=0.0, noise_rate=0.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", default="", help="time-surface parameters, e.g. coordinates=time")
    parser.add_argument("--cache", default=str(default_cache()), help="simulation cache folder ('' = none)")
    args = parser.parse_args(argv)
    settings = parse_settings(args.set)
    cache = Path(args.cache) if args.cache else None
    header = ["rotation", "events", "coverage %", "median %", "bias %", "bad_fit", "too_near"]
    rows = []
    for label, axis, share in CASES:
        config = case_config(label, axis, share)
        rec = recording_for(config, 0, cache)
        run = run_improved(rec, rotation=None if axis is None else "groundtruth", **settings)
        m, counts = run.metrics(), run.result.counts["time_surface"]
        log(f"{label}: {m['events']:,} events, coverage {m['coverage_pct']:.1f} %, median {m['median_rel_pct']:.2f} %")
        rows.append([label, f"{m['events']:,}", fmt(m["coverage_pct"]), fmt(m["median_rel_pct"], 2),
                     fmt(m["bias_pct"], 2), f"{counts['bad_fit']:,}", f"{counts['too_near']:,}"])
    print_tables(header, rows, f"Constant rotation, wall at {DEPTH:g} m, slide {SPEED:g} m/s, {DURATION:g} s, "
                 f"no noise, no mismatch; time surface {settings or 'defaults'}", blank_after=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
