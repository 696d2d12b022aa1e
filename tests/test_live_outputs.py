"""tofnet live's outputs replace nothing tofnet did not write: --json is checked before the run (an
existing file only with --force, never the recording), and --out DIR is a folder of tofnet's own
(a manifest), written under a temporary name and put in place when the run ends."""

import json
import os

import pytest

from formats_helpers import pattern_recording
from tofnet.cli import main
from tofnet.errors import TofnetError
from tofnet.io.arrays import write_npz_recording
from tofnet.io.guard import MANIFEST

SPAN_US = 100_000


@pytest.fixture(scope="module")
def recording_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("live-outputs") / "pattern.npz"
    write_npz_recording(path, pattern_recording(SPAN_US))
    return path


def live(recording, *options):
    return main(["live", "--replay", str(recording), "--speed", "100", "--velocity", "0,0,1", "--png-every", "0.01s",
                 *[str(option) for option in options]])


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def no_work(monkeypatch):
    """Opening the recording fails the test: a refusal must come first."""
    import tofnet.io.source

    def opened(*args, **kwargs):
        raise AssertionError("the recording was opened before the outputs were checked")
    monkeypatch.setattr(tofnet.io.source, "open_recording", opened)


def leftovers(folder) -> list[str]:
    return [name for name in os.listdir(folder) if name.endswith(".part")]


def test_an_existing_json_is_refused_before_the_run_and_replaced_only_with_force(recording_file, tmp_path,
                                                                                  capsys, monkeypatch):
    stats = tmp_path / "live.json"
    stats.write_text("mine")
    with monkeypatch.context() as patch:
        no_work(patch)
        assert live(recording_file, "--no-view", "--json", stats) == 2
    err = one_line(capsys)
    assert str(stats) in err and "pass --force" in err and stats.read_text() == "mine"
    assert live(recording_file, "--no-view", "--json", stats, "--force") == 0
    assert json.loads(stats.read_text())["events_in"] > 0


def test_json_never_replaces_the_recording_even_with_force(recording_file, tmp_path, capsys, monkeypatch):
    before = recording_file.read_bytes()
    no_work(monkeypatch)
    assert live(recording_file, "--no-view", "--json", recording_file, "--force") == 2
    assert "would overwrite the input" in one_line(capsys) and recording_file.read_bytes() == before


def test_json_and_out_naming_the_same_place_are_refused(recording_file, tmp_path, capsys, monkeypatch):
    no_work(monkeypatch)
    assert live(recording_file, "--out", tmp_path / "same", "--json", tmp_path / "same") == 2
    assert "name the same file" in one_line(capsys) and not (tmp_path / "same").exists()
    assert live(recording_file, "--out", tmp_path / "frames", "--json", tmp_path / "frames" / "s.json") == 2
    assert "--json" in one_line(capsys) and not (tmp_path / "frames").exists()


@pytest.mark.parametrize("name", ["depth-000099.png", "notes.txt"])
def test_a_folder_holding_a_file_tofnet_did_not_write_is_refused_untouched(recording_file, tmp_path, capsys,
                                                                           monkeypatch, name):
    frames = tmp_path / "frames"
    frames.mkdir()
    (frames / name).write_text("mine")
    with monkeypatch.context() as patch:
        no_work(patch)
        for force in ([], ["--force"]):
            assert live(recording_file, "--out", frames, *force) == 2
            err = one_line(capsys)
            assert str(frames) in err and name in err and "did not write" in err
    assert os.listdir(frames) == [name] and (frames / name).read_text() == "mine" and not leftovers(tmp_path)


def test_an_earlier_runs_frames_are_replaced_only_with_force(recording_file, tmp_path, capsys):
    frames = tmp_path / "frames"
    assert live(recording_file, "--out", frames) == 0
    assert "PNG frames -> " + str(frames) in capsys.readouterr().out
    written = sorted(os.listdir(frames))
    assert MANIFEST in written and any(name.startswith("depth-") for name in written)
    listed = json.loads((frames / MANIFEST).read_text())
    assert listed["written_by"] == "tofnet live" and sorted(listed["files"]) == [n for n in written if n != MANIFEST]
    first = {name: (frames / name).stat().st_mtime_ns for name in written}
    assert live(recording_file, "--out", frames) == 2
    err = one_line(capsys)
    assert str(frames) in err and "pass --force" in err
    assert {name: (frames / name).stat().st_mtime_ns for name in os.listdir(frames)} == first
    (frames / "depth-000001.png").unlink()  # an earlier frame gone: the new run's come in its place
    assert live(recording_file, "--out", frames, "--force") == 0
    assert (frames / "depth-000001.png").is_file() and not leftovers(tmp_path)


def test_a_failed_run_leaves_the_earlier_frames_untouched(recording_file, tmp_path, capsys, monkeypatch):
    frames = tmp_path / "frames"
    assert live(recording_file, "--out", frames) == 0
    before = {name: (frames / name).read_bytes() for name in os.listdir(frames)}
    import tofnet.live

    def failing(source, network, *, tick=None, **options):
        for _ in range(3):
            tick(True)
        raise TofnetError("the camera went away")
    monkeypatch.setattr(tofnet.live, "run_live", failing)
    assert live(recording_file, "--out", frames, "--force") == 2
    assert "the camera went away" in one_line(capsys)
    assert {name: (frames / name).read_bytes() for name in os.listdir(frames)} == before
    assert not leftovers(tmp_path)


def test_a_symlinked_folder_is_refused_and_its_target_untouched(recording_file, tmp_path, capsys, monkeypatch):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "depth-000001.png").write_text("mine")
    (tmp_path / "linkdir").symlink_to(outside)
    no_work(monkeypatch)
    for force in ([], ["--force"]):
        assert live(recording_file, "--out", tmp_path / "linkdir", *force) == 2
        err = one_line(capsys)
        assert str(tmp_path / "linkdir") in err and "symbolic link" in err
    assert os.listdir(outside) == ["depth-000001.png"] and (outside / "depth-000001.png").read_text() == "mine"


def test_a_folder_in_place_of_a_frame_is_one_line(recording_file, tmp_path, capsys, monkeypatch):
    frames = tmp_path / "frames2"
    (frames / "depth-000005.png").mkdir(parents=True)
    no_work(monkeypatch)
    assert live(recording_file, "--out", frames, "--force") == 2
    assert "depth-000005.png" in one_line(capsys) and (frames / "depth-000005.png").is_dir()


def test_ctrl_c_ends_a_run_with_its_summary_its_json_and_its_frames(recording_file, tmp_path, capsys, monkeypatch):
    """Ctrl-C is how a camera run ends without --seconds: it ends the run after the packet being fed, as
    --seconds does (the summary, --json saying so, the frames in place), and exits 130 as an interrupt does."""
    import signal

    import tofnet.live

    replayed = tofnet.live.ReplaySource.packets

    def packets(self):
        for i, packet in enumerate(replayed(self)):
            if i == 20:
                os.kill(os.getpid(), signal.SIGINT)  # a real SIGINT, as the terminal sends
            yield packet
    monkeypatch.setattr(tofnet.live.ReplaySource, "packets", packets)
    frames, stats = tmp_path / "frames", tmp_path / "s.json"
    assert live(recording_file, "--out", frames, "--json", stats) == 130
    captured = capsys.readouterr()
    assert captured.err.splitlines()[-1] == "tofnet live: interrupted (Ctrl-C); the summary covers the run up to it"
    assert "delay          p50" in captured.out and "ended          by Ctrl-C" in captured.out
    assert "PNG frames -> " + str(frames) in captured.out and (frames / MANIFEST).is_file()
    summary = json.loads(stats.read_text())
    assert summary["interrupted"] is True and summary["packets"] == 21  # the packet being fed, none after it
    assert 0 < summary["events_in"] < len(pattern_recording(SPAN_US).events) and summary["depth_out"] > 0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler and not leftovers(tmp_path)


def test_a_second_ctrl_c_keeps_the_whole_frames_it_wrote(recording_file, tmp_path, capsys, monkeypatch):
    """A second Ctrl-C (run_live raises KeyboardInterrupt, the first having not yet ended it) stops at once: the
    frames shown so far are kept, each whole; no summary."""
    import tofnet.live

    def interrupted(source, network, *, tick=None, **options):
        for _ in range(3):
            tick(True)
        raise KeyboardInterrupt
    monkeypatch.setattr(tofnet.live, "run_live", interrupted)
    frames = tmp_path / "frames"
    assert live(recording_file, "--out", frames, "--json", tmp_path / "s.json") == 130
    captured = capsys.readouterr()
    assert "interrupted" in captured.err and "3 PNG frames -> " + str(frames) in captured.out
    assert sorted(os.listdir(frames)) == [MANIFEST, "depth-000001.png", "depth-000002.png", "depth-000003.png"]
    assert not (tmp_path / "s.json").exists() and not leftovers(tmp_path)


def test_live_says_where_the_rotation_comes_from_as_run_does(tmp_path, capsys):
    rec = tmp_path / "wobble"
    assert main(["simulate", "wobble_slider", str(rec), "--duration", "0.05", "--quiet"]) == 0
    assert main(["run", str(rec), "--out", str(tmp_path / "d.npz"), "--quiet"]) == 0
    said = [line for line in capsys.readouterr().out.splitlines() if line.startswith("rotation ")]
    assert len(said) == 1 and "eq. 7" in said[0]
    assert main(["live", "--replay", str(rec), "--speed", "100", "--no-view"]) == 0
    assert [line for line in capsys.readouterr().out.splitlines() if line.startswith("rotation ")] == said
