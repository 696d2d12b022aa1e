"""Error and coverage against a threshold on the fit quality (``tofnet.eval.quality``, ``tofnet eval --quality``)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.eval.match import match_estimates
from tofnet.eval.quality import quality_curve
from tofnet.events import DEPTH_DTYPE, make_events
from tofnet.io import write_depth, write_ecd
from tofnet.io.npy import write_npz
from tofnet.io.recording import Intrinsics

RMS = [0.05, 0.1, 0.2, 0.3]
POINTS = [20, 12, 9, 8]


def _case():
    # Five events at 2 m; four estimates whose error grows as their fit gets worse.
    events = make_events([0] * 5, list(range(5)), [0] * 5, [1] * 5)
    gt = np.full(5, 2.0)
    depth = np.empty(4, DEPTH_DTYPE)
    depth["step"], depth["t"], depth["y"] = 2, 3000, 0
    depth["x"], depth["z"] = [0, 1, 2, 3], [2.02, 2.1, 1.6, 3.0]  # 1 %, 5 %, -20 %, +50 %
    quality = {"step": depth["step"].copy(), "x": depth["x"].copy(), "y": depth["y"].copy(),
               "t_event": np.zeros(4, np.int64), "points": np.array(POINTS, np.uint16),
               "rms_px": np.array(RMS, np.float32), "gx": np.zeros(4, np.float32), "gy": np.zeros(4, np.float32)}
    return events, gt, depth, quality


def test_a_stricter_threshold_keeps_fewer_better_estimates():
    events, gt, depth, quality = _case()
    records = np.empty(4, [(k, v.dtype) for k, v in quality.items()])
    for k, v in quality.items():
        records[k] = v
    matches = match_estimates(depth, events, gt, t0_us=0, timestep_us=1000, latency_steps=2)
    curve = quality_curve(depth, records, matches, len(events), "rms_px", (0.05, 0.1, 0.2, math.inf))
    assert [p.kept for p in curve] == [1, 2, 3, 4]
    assert [p.coverage for p in curve] == pytest.approx([0.2, 0.4, 0.6, 0.8])
    assert curve[0].errors.median_rel_pct == pytest.approx(1.0, rel=1e-3)
    assert curve[-1].errors.median_rel_pct == pytest.approx(12.5, rel=1e-3)  # median of 1, 5, 20, 50
    by_points = quality_curve(depth, records, matches, len(events), "points", (0, 10, 20))
    assert [p.kept for p in by_points] == [4, 2, 1]


def test_eval_finds_the_quality_file_beside_the_depth_and_refuses_a_foreign_one(tmp_path, capsys):
    events, gt, depth, quality = _case()
    write_ecd(tmp_path / "rec", events, intrinsics=Intrinsics(10, 10, 2, 2), sensor_size=(5, 1), gt_depth=gt)
    write_depth(tmp_path / "d.npz", depth, t0_us=0, timestep_us=1000, latency_steps=2)
    write_npz(tmp_path / "d.time_surface.quality.npz", quality)
    assert main(["eval", str(tmp_path / "rec"), str(tmp_path / "d.npz"), "--json", str(tmp_path / "m.json")]) == 0
    assert "by fit quality (estimates with rms_px <= τ" in capsys.readouterr().out
    curves = json.loads((tmp_path / "m.json").read_text())["quality_curves"]
    assert [p["kept"] for p in curves["rms_px"]][-1] == 4 and curves["points"][0]["threshold"] == 0
    other = dict(quality, x=quality["x"][::-1].copy())
    write_npz(tmp_path / "other.npz", other)
    assert main(["eval", str(tmp_path / "rec"), str(tmp_path / "d.npz"), "--quality", str(tmp_path / "other.npz")]) == 2
    err = capsys.readouterr().err
    assert "same step and pixel" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
