"""Plan keys that say how a recording is read (intrinsics, calib, velocity, columns, topics, start, duration)."""

import json

import numpy as np
import pytest

from tofnet.batch import PlanError, expand, load_plan
from tofnet.batch.worker import run_task
from tofnet.cli import main

from formats_helpers import pattern_recording


@pytest.fixture
def folder(tmp_path):
    recording = pattern_recording()
    events = recording.events
    # A plain (n, 4) array in MVSEC's order, and nothing beside it: no calibration, no poses.
    rows = np.column_stack([events["x"], events["y"], (events["t"] - events["t"][0]) * 1e-6, events["p"]])
    np.save(tmp_path / "plain.npy", rows)
    (tmp_path / "cam.yaml").write_text("cam0:\n  camera_model: pinhole\n  intrinsics: [60.0, 61.0, 31.5, 23.25]\n"
                                       "  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n"
                                       "  resolution: [64, 48]\n")
    return tmp_path


def write(folder, text):
    path = folder / "plan.yaml"
    path.write_text(text)
    return path


def test_reading_keys_plan_wide_and_per_recording(folder):
    plan = load_plan(write(folder, "velocity: [0.5, 0, 0]\ncolumns: x,y,t,p\nstart: 50ms\n"
                                   "recordings:\n  - plain.npy\n"
                                   "  - {path: plain.npy, name: windowed, calib: cam.yaml, duration: 100ms}\n"
                                   "  - {path: plain.npy, name: other, intrinsics: '60,61,31.5,23.25', start: 0s}\n"))
    first, second, third = plan.recordings
    assert first.options == {"velocity": "0.5,0,0", "columns": "x,y,t,p", "start": "50ms"}
    assert second.options == {"velocity": "0.5,0,0", "columns": "x,y,t,p", "start": "50ms",
                               "calib": str(folder / "cam.yaml"), "duration": "100ms"}
    assert third.options["start"] == "0s" and third.options["intrinsics"] == "60,61,31.5,23.25"
    ids = [task.task_id for task in expand(plan)]
    assert len(set(ids)) == 3
    # A task reads as `tofnet run` with the same options would.
    row = run_task(expand(plan)[1])
    assert row["status"] == "ok", row["error"]
    assert main(["run", str(folder / "plain.npy"), "--columns", "x,y,t,p", "--calib", str(folder / "cam.yaml"),
                 "--velocity", "0.5,0,0", "--start", "50ms", "--duration", "100ms", "--quiet",
                 "--out", str(folder / "d.npz"), "--json", str(folder / "s.json")]) == 0
    alone = json.loads((folder / "s.json").read_text())
    assert 0 < row["events_in"] == alone["events_in"] < len(np.load(folder / "plain.npy"))
    assert row["depth_out"] == alone["depth_out"] > 0
    # Without calibration (nothing beside the file) the task fails with the reader's one line.
    plan = load_plan(write(folder, "recordings: [plain.npy]\ncolumns: x,y,t,p\nvelocity: 0.5,0,0\n"))
    row = run_task(expand(plan)[0])
    assert row["status"] == "failed" and "\n" not in row["error"]


@pytest.mark.parametrize("text, line, expected", [
    ("recordings: [plain.npy]\nintrinsics: 1,2,3\n", 2, "intrinsics: expected fx,fy,cx,cy"),
    ("recordings:\n  - {path: plain.npy,\n     calib: nothing.yaml}\n", 3, "recordings[0].calib: "),
    ("recordings:\n  - {path: plain.npy, velocity: fast}\n", 2, "recordings[0].velocity: expected TX,TY,TZ"),
    ("recordings: [plain.npy]\ncolumns: x,y,z,p\n", 2, "columns: columns must name t, x, y and p"),
    ("recordings:\n  - {glob: '*.npy', topics: [events]}\n", 2, "recordings[0].topics: expected a mapping"),
    ("recordings: [plain.npy]\nstart: soon\n", 2, "start: expected a time like"),
    ("recordings:\n  - {path: plain.npy, duration: 1s, until: 2s}\n", 2, "duration and until: give one"),
    ("recordings: [plain.npy]\nintrinsics: 1,1,1,1\ncalib: cam.yaml\n", 3, "intrinsics and calib"),
    ("recordings:\n  - {scenario: slider, start: 1s}\n", 2, "recordings[0].start: unknown key for a scenario"),
    ("recordings:\n  - {path: plain.npy, topics: {event: /dvs}}\n", 2, "topics: unknown role 'event'"),
    ("recordings:\n  - {path: plain.npy, camera: cam3}\n", 2, "recordings[0].camera: picks a camera"),
])
def test_errors_name_the_line_and_the_key(folder, text, line, expected):
    path = write(folder, text)
    with pytest.raises(PlanError) as err:
        load_plan(path)
    message = str(err.value)
    assert message.startswith(f"{path}:{line}: ") and expected in message and "\n" not in message, message
