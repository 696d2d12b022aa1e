"""The time surface's error and coverage by fit quality on the random scenes (by hand, not in CI).

    python benchmarks/motion_quality.py                                   # reversing and steady, variant 100, 1 s
    python benchmarks/motion_quality.py --motions forward,shake

Each scene is simulated and run as ``motion_sweep.py`` does (its cache, seed = variant; a
shaking camera with eq. 7, ω from the 1 kHz poses), the time-surface estimator with
``max_rms_px`` 1 (``--set``) so that the curve goes past the default 0.25 px, and scored with
``tofnet.eval.quality.quality_curve`` (what ``tofnet eval --quality`` prints) at the thresholds
below: coverage per input event, median and bias of the estimates whose fit lies within
``τ`` px rms of its points. One column group per scene; a markdown table goes to stdout.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import as_written, default_backend, log, recording_for, run_improved  # noqa: E402
from motion_sweep import parse_settings, parse_variants, scene_options  # noqa: E402

from tofnet.eval.quality import quality_curve  # noqa: E402
from tofnet.sim.scenarios import scenario  # noqa: E402

THRESHOLDS = (0.1, 0.15, 0.2, 0.25, 0.35, 0.5, 0.75, 1.0)


def main(argv: list[str] | None = None) -> int:
    args = scene_options(__doc__, "reversing,steady", "100", "max_rms_px=1").parse_args(argv)
    settings = parse_settings(args.set)
    backend = args.backend or default_backend()
    cache = Path(args.cache) if args.cache else None
    columns: list[tuple[str, list]] = []
    for motion in filter(None, args.motions.split(",")):
        for variant in parse_variants(args.variants):
            config = scenario(f"random_{motion}:{variant}", args.duration)
            rec = recording_for(config, variant, cache)
            rotation = None
            if motion == "shake":
                rec, rotation = as_written(rec, config, variant), "groundtruth"
            run = run_improved(rec, backend=backend, rotation=rotation, **settings)
            e = run.evaluation
            curve = quality_curve(run.result.depth, run.result.outputs["time_surface.quality"], e.matches,
                                  e.events_in, "rms_px", THRESHOLDS)
            log(f"{config.name}: {e.events_in:,} events, {e.estimates:,} estimates")
            columns.append((f"{motion}:{variant}", curve))
    header = ["τ px"]
    for name, _ in columns:
        header += [f"{name} coverage %", "median %", "bias %"]
    print(f"Time surface by fit quality, {args.duration:g} s, backend {backend}, time surface {settings}")
    print()
    print("| " + " | ".join(header) + " |")
    print("|" + "---:|" * len(header))
    for i, tau in enumerate(THRESHOLDS):
        cells = [f"{tau:g}"]
        for _, curve in columns:
            p = curve[i]
            cells += [f"{100 * p.coverage:.2f}", f"{p.errors.median_rel_pct:.1f}", f"{p.errors.bias_rel_pct:+.1f}"]
        print("| " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
