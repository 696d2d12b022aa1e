"""`tofnet demo` runs the whole pipeline with no arguments but an output folder."""

import json

from tofnet.cli import main


def test_demo_simulates_runs_scores_and_draws(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--duration", "0.1"]) == 0
    printed = capsys.readouterr().out
    for kind in ("depthmap", "histogram", "error", "cloud", "compare"):
        png = out / "figures" / f"{kind}.png"
        assert png.stat().st_size > 10_000 and str(png) in printed
    scores = json.loads((out / "eval.json").read_text())
    assert scores["estimates"] > 1000 and 0 < scores["coverage"] < 1
    improved = json.loads((out / "eval_improved.json").read_text())
    assert improved["estimates"] > 1000 and improved["median_rel_pct"] < scores["median_rel_pct"]
    assert (out / "depth.npz").exists() and (out / "depth_improved.npz").exists()
    assert (out / "recording" / "events.txt").exists()
    assert "Time-surface estimator" in printed and "Paper's network" in printed
    assert "[4/4]" in printed and "Open the PNGs" in printed
