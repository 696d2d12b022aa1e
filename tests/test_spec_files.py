"""A spec reads only files in its own folder: one from someone else cannot make tofnet read, and
quote in an error, a file elsewhere (``/proc/self/environ``, ``~/.netrc``); the user names such a
file themselves with ``--set``."""

from pathlib import Path

import numpy as np
import pytest

from tofnet.batch import load_plan
from tofnet.errors import SpecError
from tofnet.io.depth import read_depth
from tofnet.io.spec import load_spec

from test_reliability_outputs import folder, one_line_error  # noqa: F401  (a fixture and a helper)

SECRET = "API_KEY=sk-live-0123456789abcdefghij"


def spec_naming(folder: Path, samples: str, *, param: str = "samples") -> Path:
    """A paper network in ``folder/spec.yaml`` whose velocity (or angular velocity) reads ``samples``."""
    rotation = (f"  angular_velocity: {{type: AngularVelocityProcess, source: gyro, {param}: '{samples}'}}\n"
                if param == "imu" else "")
    folder.mkdir(parents=True, exist_ok=True)
    spec = folder / "spec.yaml"
    spec.write_text("processes:\n"
                    "  input: {type: InputProcess, sensor_size: [240, 180], timestep: 1ms, refractory: 60ms}\n"
                    "  time_of_travel: {type: TimeOfTravelProcess, distance: 1, counter_bits: 8}\n"
                    "  depth: {type: DepthProcess, min_depth: 0.05, max_depth: 20}\n"
                    "  velocity: {type: VelocityProcess, source: samples, "
                    f"samples: '{samples if param == 'samples' else 'vel.txt'}', intrinsics: [200, 200, 119.5, 89.5]}}\n"
                    + rotation +
                    "connections:\n  - input.events -> time_of_travel.events\n"
                    "  - time_of_travel.counts -> depth.counts\n  - velocity.a_t -> depth.a_t\n"
                    + ("  - angular_velocity.b_w -> depth.b_w\n" if rotation else ""))
    return spec


@pytest.fixture
def secret(tmp_path) -> Path:
    path = tmp_path / "home" / ".env"
    path.parent.mkdir()
    path.write_text(f"{SECRET} 1 2 3\n")
    return path


@pytest.mark.parametrize("how", ["absolute", "dot-dot", "symlink", "symlinked folder"])
@pytest.mark.parametrize("param", ["samples", "imu"])
def test_a_file_outside_the_spec_folder_is_refused_before_it_is_read(tmp_path, secret, how, param):
    """Links too: a stranger's bundle may hold ``vel.txt -> ~/.env`` (tar keeps links); shared data is named on
    the command line."""
    specs = tmp_path / "specs"
    specs.mkdir()
    named = {"absolute": str(secret), "dot-dot": "../home/.env", "symlink": "link.txt",
             "symlinked folder": "home/.env"}[how]
    if how == "symlink":
        (specs / "link.txt").symlink_to(secret)
    if how == "symlinked folder":
        (specs / "home").symlink_to(secret.parent, target_is_directory=True)
    spec = spec_naming(specs, named, param=param)
    with pytest.raises(SpecError) as caught:
        load_spec(spec)
    message = str(caught.value)
    process = "angular_velocity" if param == "imu" else "velocity"
    assert f"spec.yaml:{5 if param == 'samples' else 6}: processes.{process}.{param}:" in message
    assert f"lies outside the spec's folder {specs}" in message and f"--set {process}.{param}=FILE" in message
    assert "API_KEY" not in message and "\n" not in message


def test_a_file_beside_or_below_the_spec_is_read_from_the_spec_folder_wherever_tofnet_runs(tmp_path, monkeypatch):
    specs = tmp_path / "specs"
    (specs / "data").mkdir(parents=True)
    (specs / "data" / "vel.txt").write_text("0 0.5 0 0\n1 0.5 0 0\n")
    spec = spec_naming(specs, "data/vel.txt")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    network = load_spec(spec).network
    assert Path(network.process("velocity").samples) == specs / "data" / "vel.txt"  # not elsewhere/data/vel.txt
    nul = spec_naming(specs, "a\\0b.txt").read_text().replace("a\\0b.txt", "a\\x00b.txt").replace("'", '"')
    (specs / "spec.yaml").write_text(nul)  # a NUL in the name: one line, no traceback
    with pytest.raises(SpecError, match="processes.velocity.samples: .* lies outside the spec's folder"):
        load_spec(specs / "spec.yaml")


def test_a_spec_given_as_text_or_data_in_python_is_the_callers_own(tmp_path, secret):
    """Its names are kept as written (a spec written by dump_spec, or compile's JSON, reads back anywhere)."""
    from tofnet.io.spec import spec_from_dict, spec_to_dict
    text = spec_naming(tmp_path / "s", str(secret)).read_text()
    spec = load_spec(text)
    assert spec.network.process("velocity").samples == str(secret)
    assert spec_from_dict(spec_to_dict(load_spec(tmp_path / "s" / "spec.yaml".replace("spec", "spec")) if False
                                       else spec)).network.process("velocity").samples == str(secret)


def test_run_refuses_it_in_one_line_and_set_names_a_file_elsewhere(folder, tmp_path, secret, capsys):  # noqa: F811
    from tofnet.cli import main
    (tmp_path / "vel.txt").write_text("0 0.5 0 0\n1 0.5 0 0\n")
    spec = spec_naming(tmp_path / "specs", str(secret))
    out = tmp_path / "d.npz"
    assert main(["run", str(folder), "--spec", str(spec), "--out", str(out), "--quiet",
                 "--set", f"velocity.samples={tmp_path / 'vel.txt'}"]) == 0
    assert read_depth(out)[1]["summary"] is not None
    capsys.readouterr()
    (tmp_path / "bad.txt").write_text("0 0.5 0\n")  # the file --set names is the one read
    err = one_line_error(capsys, ["run", str(folder), "--spec", str(spec), "--out", str(out), "--quiet", "--force",
                                  "--set", f"velocity.samples={tmp_path / 'bad.txt'}"])
    assert "bad.txt:1: expected 4 columns" in err
    out.unlink()
    err = one_line_error(capsys, ["run", str(folder), "--spec", str(spec), "--out", str(out), "--quiet"])
    assert "lies outside the spec's folder" in err and "API_KEY" not in err and not out.exists()
    assert main(["run", str(folder), "--spec", str(spec), "--out", str(out), "--quiet",
                 "--velocity", "0.5,0,0"]) == 0  # --velocity makes it constant: the spec's file is not read


def test_a_plan_naming_such_a_spec_is_refused_at_load(tmp_path, secret):
    spec = spec_naming(tmp_path / "specs", str(secret))
    np.save(tmp_path / "a.npy", np.zeros(0))
    plan = tmp_path / "plan.yaml"
    plan.write_text(f"recordings: [a.npy]\nnetworks: [{spec}]\n")
    with pytest.raises(SpecError, match="lies outside the spec's folder") as caught:
        load_plan(plan)
    assert "API_KEY" not in str(caught.value)


@pytest.mark.parametrize("side", ["calib.txt", "events.txt", "groundtruth.txt"])
def test_a_recording_side_file_linked_out_of_its_folder_is_never_quoted(folder, tmp_path, secret, capsys, side):  # noqa: F811
    """A recording someone sends may hold ``calib.txt -> ~/.git-credentials`` (tar and git keep links): an error
    names the file and where it links, and shows none of what it holds; a file in place is quoted as before."""
    if side == "groundtruth.txt":
        secret.write_text(f"{SECRET} 1 2 3 4 5 6 7\n")  # a pose's 8 columns
    (folder / side).unlink(missing_ok=True)
    (folder / side).symlink_to(secret)
    err = one_line_error(capsys, ["info", str(folder)])
    assert f"{side}:1: " in err and "links out of its folder, to" in err and "API_KEY" not in err
    (folder / side).unlink()
    (folder / side).write_text(secret.read_text())  # the recording's own file: its field is quoted
    assert "API_KEY" in one_line_error(capsys, ["info", str(folder)])


def test_a_field_is_not_quoted_from_a_file_or_folder_linked_out_of_its_folder(tmp_path):
    """The file, its folder and the folder above are looked at (a DSEC ``disparity/`` linked to someone's
    secrets); links higher up, such as a cluster's ``/home``, are not: their files are quoted."""
    from tofnet.errors import quote_field
    secrets = tmp_path / "secrets"
    secrets.mkdir()
    (secrets / "t.txt").write_text(SECRET)
    rec = tmp_path / "rec"
    (rec / "disparity").mkdir(parents=True)
    (rec / "disparity" / "timestamps.txt").write_text("1\n")
    (rec / "linked").symlink_to(secrets, target_is_directory=True)
    (rec / "own.txt").symlink_to(rec / "disparity" / "timestamps.txt")  # a link within: quoted
    assert quote_field(rec / "disparity" / "timestamps.txt", "abc") == "'abc'"
    assert quote_field(rec / "own.txt", "abc") == "'abc'"
    shown = quote_field(rec / "linked" / "t.txt", SECRET)
    assert SECRET not in shown and "linked links out of its folder" in shown
    (tmp_path / "real_home" / "user" / "rec").mkdir(parents=True)
    (tmp_path / "home").symlink_to(tmp_path / "real_home", target_is_directory=True)
    (tmp_path / "real_home" / "user" / "rec" / "calib.txt").write_text("x")
    assert quote_field(tmp_path / "home" / "user" / "rec" / "calib.txt", "abc") == "'abc'"
