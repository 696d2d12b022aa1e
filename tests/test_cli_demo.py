"""`tofnet demo` runs the whole pipeline with no arguments but an output folder."""

import json

from tofnet.cli import main
from tofnet.errors import TofnetError


def test_demo_simulates_runs_scores_and_draws(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--duration", "0.1"]) == 0
    printed = capsys.readouterr().out
    for kind in ("depthmap", "histogram", "error", "cloud", "compare"):
        png = out / "figures" / f"{kind}.png"
        assert png.stat().st_size > 10_000 and str(png) in printed
    scores = json.loads((out / "eval.json").read_text())
    assert scores["source"] == str(out / "recording")  # not the temporary folder it was written in
    assert scores["estimates"] > 1000 and 0 < scores["coverage"] < 1
    improved = json.loads((out / "eval_improved.json").read_text())
    assert improved["estimates"] > 1000 and improved["median_rel_pct"] < scores["median_rel_pct"]
    assert (out / "depth.npz").exists() and (out / "depth_improved.npz").exists()
    assert (out / "recording" / "events.txt").exists()
    assert "Time-surface estimator" in printed and "Paper's network" in printed
    assert "[4/4]" in printed and "Open the PNGs" in printed


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def _contents(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _no_work(monkeypatch):
    import tofnet.sim.run

    def simulate(*args, **kwargs):
        raise AssertionError("the demo started before its folder was checked")
    monkeypatch.setattr(tofnet.sim.run, "simulate", simulate)


def test_demo_never_replaces_files_it_did_not_write(tmp_path, capsys, monkeypatch):
    out = tmp_path / "demo"
    for name in ("depth.npz", "depth_improved.npz", "eval.json", "eval_improved.json", "recording/events.txt",
                 "recording/calib.txt", "figures/compare.png"):
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("mine")
    before = _contents(out)
    _no_work(monkeypatch)
    for force in ([], ["--force"]):
        assert main(["demo", "--out", str(out), "--duration", "0.1", *force]) == 2
        err = _one_line(capsys)
        assert str(out) in err and "did not write" in err
    assert _contents(out) == before and not [p for p in tmp_path.iterdir() if p.name.endswith(".part")]


def test_demo_never_replaces_files_added_to_an_earlier_demos_folder(tmp_path, capsys, monkeypatch):
    """The audit's case: files inside an earlier demo's sub-folders and a user's ``.thesis.part`` were
    removed without --force, since only top-level names were compared with the manifest."""
    from tofnet.cli.demo import DEMO
    from tofnet.io.files import write_manifest

    out = tmp_path / "tofnet-demo"
    for name in ("eval.json", "figures/compare.png", "recording/events.txt"):
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("the demo's")
    write_manifest(out, DEMO)
    _no_work(monkeypatch)
    for added in ("figures/my_notes.txt", "recording/mine/data.txt", ".thesis.part"):
        (out / added).parent.mkdir(parents=True, exist_ok=True)
        (out / added).write_text("mine")
        before = _contents(out)
        for force in ([], ["--force"]):
            assert main(["demo", "--out", str(out), "--duration", "0.1", *force]) == 2
            err = _one_line(capsys)
            assert f"holding '{added}', which tofnet did not write" in err
        assert _contents(out) == before
        (out / added).unlink()


def test_demo_replaces_its_own_folder_and_only_when_it_succeeds(tmp_path, capsys, monkeypatch):
    from tofnet.io.guard import MANIFEST

    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--duration", "0.1"]) == 0
    assert str(out / "figures" / "compare.png") in capsys.readouterr().out
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["written_by"] == "tofnet demo" and "figures/compare.png" in manifest["files"]
    first = _contents(out)
    # another command's folder (a manifest, nothing foreign) needs --force; an earlier demo's does not
    other = tmp_path / "other"
    assert main(["simulate", "slider", str(other), "--duration", "0.02", "--quiet"]) == 0
    capsys.readouterr()
    with monkeypatch.context() as patch:
        _no_work(patch)
        assert main(["demo", "--out", str(other), "--duration", "0.1"]) == 2
    err = _one_line(capsys)
    assert str(other) in err and "pass --force" in err
    import tofnet.eval.plots

    def broken(*args, **kwargs):
        raise TofnetError("no figures today")
    with monkeypatch.context() as patch:
        patch.setattr(tofnet.eval.plots, "plot_all", broken)
        assert main(["demo", "--out", str(out), "--duration", "0.1", "--seed", "1"]) == 2
    assert "no figures today" in _one_line(capsys) and _contents(out) == first
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".part")]
    assert main(["demo", "--out", str(out), "--duration", "0.1", "--seed", "1"]) == 0  # rerunning just works
    assert _contents(out)["eval.json"] != first["eval.json"] and (out / MANIFEST).is_file()
