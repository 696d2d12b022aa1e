"""A file that states no sensor size (a .npy): tofnet run and live warn alike about the events outside
the 240x180 sensor they run it as, check the camera against that sensor, and tofnet info says so."""

import json

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.events import make_events

CAMERA = ["--velocity", "-0.5,0,0.1"]


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    """0.1 s of events over a 1280x720 sensor, in a .npy that does not say so."""
    rng = np.random.default_rng(3)
    n = 20_000
    path = tmp_path_factory.mktemp("unsized") / "big.npy"
    np.save(path, make_events(np.sort(rng.integers(0, 100_000, n)), rng.integers(0, 1280, n),
                              rng.integers(0, 720, n), rng.integers(0, 2, n)))
    events = np.load(path)
    return path, int(np.count_nonzero((events["x"] >= 240) | (events["y"] >= 180)))


def _warnings(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("warning")]


def test_live_warns_of_the_events_outside_the_sensor_as_run_does(big, tmp_path, capsys):
    """live ran such a file as 240x180 and dropped 95 % of its events as out of bounds with no warning."""
    path, outside = big
    intrinsics = ["--intrinsics", "200,200,120,90"]
    assert main(["run", str(path), *intrinsics, *CAMERA, "--quiet", "--out", str(tmp_path / "d.npz")]) == 0
    said = _warnings(capsys.readouterr().out)
    assert said == [f"warning        {outside:,} events lay outside the 240x180 sensor (if the recording is larger, "
                    "--sensor-size says how large)"]
    assert main(["live", "--replay", str(path), *intrinsics, *CAMERA, "--no-view", "--speed", "8"]) == 0
    assert _warnings(capsys.readouterr().out) == said
    assert main(["live", "--replay", str(path), *intrinsics, *CAMERA, "--no-view", "--speed", "8",
                 "--sensor-size", "1280x720"]) == 0
    assert _warnings(capsys.readouterr().out) == []


@pytest.mark.parametrize("command", ["run", "live"])
def test_a_principal_point_outside_the_sensor_the_network_runs_is_noted(big, tmp_path, command, capsys):
    """--intrinsics with cx 640 on a file run as 240x180 was taken silently (the check at opening needs a size)."""
    path, _ = big
    head = ["run", str(path), "--quiet", "--force", "--out", str(tmp_path / "d.npz")] if command == "run" else \
        ["live", "--replay", str(path), "--no-view", "--speed", "8"]
    note = ("note           the principal point (640, 360) px is outside the 240x180 sensor: the calibration of "
            "another camera or resolution, or a sensor size to give (--sensor-size)?")
    assert main([*head, "--intrinsics", "200,200,640,360", *CAMERA]) == 0
    assert note in capsys.readouterr().out.splitlines()
    assert main([*head, "--intrinsics", "200,200,640,360", *CAMERA, "--sensor-size", "1280x720"]) == 0
    assert "principal point" not in capsys.readouterr().out


def test_info_says_how_run_and_live_size_a_file_that_does_not_say(big, tmp_path, capsys):
    path, outside = big
    assert main(["info", str(path), "--quiet", "--json", str(tmp_path / "i.json")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert ("sensor         unknown (the file does not say); tofnet run and live take 240x180 px, the default, "
            "unless --sensor-size WxH") in lines
    assert any(line.startswith("pixels used") and line.endswith(f"; {outside:,} events beyond 240x180 px")
               for line in lines)
    facts = json.loads((tmp_path / "i.json").read_text())
    assert facts["run_sensor_size"] == [240, 180] and facts["run_sensor_size_from"] == "default"
