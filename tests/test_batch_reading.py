"""Plan keys that say how a recording is read (intrinsics, calib, velocity, columns, topics, start, duration)."""

import json

import numpy as np
import pytest

from tofnet.batch import PlanError, expand, load_plan
from tofnet.batch.worker import run_task
from tofnet.cli import main
from tofnet.errors import SpecError

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
    # and says what its reading noted (the window, the calibration), as the run's summary does
    assert row["notes"] == "; ".join(alone["notes"]) and "time window" in row["notes"], (row["notes"], alone["notes"])
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


SECRET = "API_KEY=sk-live-ABCDEF0123456789SECRET 1 2 3\n"


@pytest.mark.parametrize("text, line, key", [
    ("recordings: [../secret/token.txt]\n", 1, "recordings[0]"),
    ("recordings:\n  - {path: ../secret/token.txt}\n", 2, "recordings[0].path"),
    ("recordings: [plain.npy]\ncalib: sub/../../secret/cam.yaml\n", 2, "calib"),
    ("recordings: [plain.npy]\nnetworks: [../secret/spec.yaml]\n", 2, "networks[0]"),
])
def test_a_plan_reads_no_file_out_of_its_folder_by_a_relative_path(folder, text, line, key):
    """The audit's case: ``{path: ../../secret/token.txt}`` was read, its first field quoted into results.csv."""
    (folder / "secret").mkdir()
    for name in ("token.txt", "cam.yaml", "spec.yaml"):
        (folder / "secret" / name).write_text(SECRET)
    plans = folder / "plans"
    plans.mkdir()
    (plans / "plain.npy").symlink_to(folder / "plain.npy")
    (plans / "sub").mkdir()
    path = write(plans, text)
    with pytest.raises(PlanError) as err:
        load_plan(path)
    assert str(err.value).startswith(f"{path}:{line}: {key}: '") and "leaves the plan's folder (..); give an " \
        "absolute path to look elsewhere" in str(err.value), str(err.value)
    # an absolute name is the user's to see in the plan, and the output may be anywhere (tofnet writes only there)
    plan = load_plan(write(plans, f"output: ../results\nrecordings: [{folder / 'plain.npy'}]\n"))
    assert plan.recordings[0].path == str(folder / "plain.npy") and plan.output.resolve() == folder / "results"


def test_a_task_quotes_no_field_of_a_file_outside_the_plans_folder(folder):
    """A file named absolutely, or through a link out of the plan's folder, is read, but its fields stay out
    of the terminal and results.csv; a file of the plan's folder is quoted as before."""
    (folder / "secret").mkdir()
    (folder / "secret" / "token.txt").write_text(SECRET)
    plans = folder / "plans"
    plans.mkdir()
    (plans / "link.txt").symlink_to(folder / "secret" / "token.txt")
    (plans / "own.txt").write_text(SECRET)
    plan = load_plan(write(plans, f"recordings:\n  - {folder / 'secret' / 'token.txt'}\n  - link.txt\n  - own.txt\n"))
    absolute, linked, own = (run_task(task)["error"] for task in expand(plan))
    assert "got a field not shown (" in absolute and "token.txt is outside the plan's folder)" in absolute, absolute
    assert "links out of its folder, to " in linked, linked
    assert "sk-live" not in absolute + linked and "\n" not in absolute + linked
    assert "got 'API_KEY=sk-live-ABCDEF0123456789SECRET'" in own, own
    # a calib: file outside the plan's folder is read on the client, and quoted no more there
    (folder / "secret" / "cam.yaml").write_text(f"cam0:\n  camera_model: {SECRET}  intrinsics: [1, 1, 1, 1]\n")
    with pytest.raises(PlanError) as err:
        load_plan(write(plans, f"recordings: [own.txt]\ncalib: {folder / 'secret' / 'cam.yaml'}\n"))
    assert "sk-live" not in str(err.value) and "cam.yaml is outside the plan's folder)" in str(err.value), err.value
    # a spec named absolutely: the line of its fault, neither its keys nor its values (40 characters were quoted)
    (folder / "secret" / "net.yaml").write_text(f"name: x\nprocesses:\n  input: {{type: InputProcess, timestep: "
                                                f"'{SECRET}'}}\n")
    (plans / "net.yaml").write_text((folder / "secret" / "net.yaml").read_text())
    with pytest.raises(SpecError) as err:
        load_plan(write(plans, f"recordings: [own.txt]\nnetworks: [{folder / 'secret' / 'net.yaml'}]\n"))
    assert str(err.value).startswith(f"{folder / 'secret' / 'net.yaml'}:3: not a spec tofnet can load: a field not "
                                     "shown ("), err.value
    assert "sk-live" not in str(err.value) and "timestep" not in str(err.value), err.value
    with pytest.raises(SpecError, match="net.yaml:3: processes.input.timestep: .* got 'API_KEY=sk-live"):
        load_plan(write(plans, "recordings: [own.txt]\nnetworks: [net.yaml]\n"))  # its own folder's: quoted
