"""Trust is explicit (issue 27 item 1): a spec or plan imports a module only when the user allows it."""

import os
import subprocess
import sys
import logging
import uuid
from pathlib import Path

import pytest

from tofnet.batch import load_plan
from tofnet.cli import build_parser, main
from tofnet.errors import SpecError
from tofnet.io import trust
from tofnet.io.spec import load_spec, spec_from_dict

ROOT = Path(__file__).resolve().parents[1]
BODY = "processes:\n  input: {{type: InputProcess, sensor_size: [10, 8]}}\n  gate: {{type: '{0}'}}\n" \
       "connections: [input.events -> gate.events]\n"


def canary(folder: Path) -> tuple[str, str, Path]:
    """A module in ``folder`` that leaves a marker file when imported, with a process type."""
    name = f"trust_canary_{uuid.uuid4().hex[:8]}"
    marker = folder / f"{name}.ran"
    (folder / f"{name}.py").write_text(
        f"import pathlib\npathlib.Path({str(marker)!r}).write_text('ran')\n"
        "from tofnet.testing import ParityGateProcess\n"
        f"class {name.title().replace('_', '')}Process(ParityGateProcess):\n    pass\n")
    return name, f"{name}:{name.title().replace('_', '')}Process", marker


def tofnet_cli(args, cwd, env_extra=None):
    """``python -m tofnet ARGS`` in ``cwd`` with this tree on PYTHONPATH (as a user runs it)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), **(env_extra or {})}
    env.pop(trust.ENV_ALLOW_IMPORT, None)
    return subprocess.run([sys.executable, "-m", "tofnet", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def one_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    return lines[0]


# ---------------------------------------------------------------- the reproducers

def test_this_does_not_print_the_zen_of_python(tmp_path):
    (tmp_path / "zen.yaml").write_text(BODY.format("this:X"))
    done = tofnet_cli(["compile", "zen.yaml"], tmp_path)
    assert "Beautiful is better than ugly" not in done.stdout + done.stderr
    assert done.returncode == 2
    assert one_line(done.stderr) == (
        "tofnet compile: error: zen.yaml:3: processes.gate.type: process type 'this:X' imports module 'this', "
        "which runs its code; if you trust it, allow it with --allow-import this (or TOFNET_ALLOW_IMPORT=this; "
        "allow_import=['this'] in Python)")


def test_venv_main_does_not_run(tmp_path):
    (tmp_path / "venv.yaml").write_text(BODY.format("venv.__main__:X"))
    before = sorted(os.listdir(tmp_path))
    done = tofnet_cli(["compile", "venv.yaml"], tmp_path)
    assert done.returncode == 2 and "--allow-import venv.__main__" in one_line(done.stderr)
    assert sorted(os.listdir(tmp_path)) == before  # no virtual environment was created


def test_a_module_beside_the_spec_never_runs_from_python_m_tofnet(tmp_path):
    name, type_name, marker = canary(tmp_path)
    (tmp_path / "spec.yaml").write_text(BODY.format(type_name))
    refused = tofnet_cli(["compile", "spec.yaml"], tmp_path)
    assert refused.returncode == 2 and f"--allow-import {name}" in one_line(refused.stderr)
    allowed = tofnet_cli(["compile", "spec.yaml", "--allow-import", name], tmp_path)
    assert allowed.returncode == 2 and f"--allow-import: no module '{name}' on the Python path" \
        in one_line(allowed.stderr)  # not on sys.path: refused with the option, before the spec is read
    assert not marker.exists()
    named = tofnet_cli(["compile", "spec.yaml", "--allow-import", name], tmp_path,
                       {"PYTHONPATH": f"{ROOT}{os.pathsep}{tmp_path}"})  # the user named the folder
    assert named.returncode == 0, named.stderr
    assert marker.exists()


def test_the_spec_folder_is_refused_in_python_unless_named_in_pythonpath(tmp_path, monkeypatch):
    name, type_name, marker = canary(tmp_path)
    (tmp_path / "spec.yaml").write_text(BODY.format(type_name))
    monkeypatch.syspath_prepend(str(tmp_path))  # as `python script.py` beside the spec would
    monkeypatch.delenv("PYTHONPATH", raising=False)
    with pytest.raises(SpecError, match=rf"processes.gate.type: module '{name}' would be imported from the "
                                        r"spec's own folder .*; name that folder in PYTHONPATH"):
        load_spec(tmp_path / "spec.yaml", allow_import=[name])
    assert not marker.exists() and name not in sys.modules
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    network = load_spec(tmp_path / "spec.yaml", allow_import=[name]).network
    assert marker.exists() and type(network.process("gate")).__name__.startswith("TrustCanary")
    monkeypatch.delitem(sys.modules, name)


def test_allowed_by_environment_or_argument_from_another_folder(tmp_path, monkeypatch):
    lib = tmp_path / "lib"
    lib.mkdir()
    name, type_name, marker = canary(lib)
    monkeypatch.syspath_prepend(str(lib))
    text = BODY.format(type_name)
    with pytest.raises(SpecError, match=f"allow it with --allow-import {name} "):
        load_spec(text)
    assert not marker.exists()
    monkeypatch.setenv(trust.ENV_ALLOW_IMPORT, f"other_module, {name}")
    assert load_spec(text).network.process("gate").parity == 0
    assert marker.exists()
    monkeypatch.delitem(sys.modules, name)


def test_a_package_allows_its_submodules_and_nothing_else():
    assert trust.allowed_imports(["pkg_zz", "a.b c"]) == ("pkg_zz", "a.b", "c")
    assert trust.check_import("pkg_zz.sub:X", ("pkg_zz",)) == "pkg_zz.sub"  # nothing is imported
    with pytest.raises(SpecError, match="--allow-import pkg_zzz"):
        trust.check_import("pkg_zzz:X", ("pkg_zz",))
    with pytest.raises(SpecError, match="expected a module name"):
        trust.allowed_imports(["../evil"])
    with pytest.raises(SpecError, match="is not 'package.module:ClassName'"):
        trust.check_import(".rel:X", ("rel",))


def test_already_imported_modules_and_entry_points_need_no_opt_in(tmp_path, monkeypatch):
    import tofnet.testing  # noqa: F401 - imported: naming it again runs nothing
    assert spec_from_dict({"processes": {"input": {"type": "InputProcess", "sensor_size": [10, 8]},
                                         "gate": {"type": "tofnet.testing:ParityGateProcess"}},
                           "connections": ["input.events -> gate.events"]}).network
    name, type_name, marker = canary(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))

    class EntryPoint:
        value = type_name
    monkeypatch.setattr(trust, "entry_points", lambda group: [EntryPoint()])
    assert load_spec(BODY.format(type_name)).network and marker.exists()  # the user installed that package
    monkeypatch.delitem(sys.modules, name)


def test_every_command_that_loads_a_spec_or_plan_takes_allow_import():
    parser = build_parser()
    for words in (["run", "rec"], ["plot", "units", "rec"], ["compile", "s.yaml"], ["batch", "p.yaml"]):
        assert parser.parse_args([*words, "--allow-import", "json", "--allow-import", "tofnet.testing"]) \
            .allow_import == ["json", "tofnet.testing"]


# ---------------------------------------------------------------- plans

def test_a_plan_naming_such_a_spec_needs_the_opt_in_too(tmp_path, monkeypatch, capsys):
    import numpy as np

    from tofnet.events import make_events
    lib = tmp_path / "lib"
    lib.mkdir()
    name, type_name, marker = canary(lib)
    monkeypatch.syspath_prepend(str(lib))
    np.save(tmp_path / "a.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 0]))
    (tmp_path / "net.yaml").write_text(BODY.format(type_name))
    (tmp_path / "plan.yaml").write_text("recordings: [a.npy]\nnetworks: [net.yaml]\n")
    with pytest.raises(SpecError, match=rf"net.yaml:3: processes.gate.type: .*--allow-import {name} "):
        load_plan(tmp_path / "plan.yaml")
    assert main(["batch", str(tmp_path / "plan.yaml"), "--check"]) == 2
    assert f"--allow-import {name}" in one_line(capsys.readouterr().err)
    assert not marker.exists()
    plan = load_plan(tmp_path / "plan.yaml", allow_import=[name])
    assert plan.networks[0].allow_import == (name,)  # the workers get the same opt-in
    assert main(["batch", str(tmp_path / "plan.yaml"), "--check", "--allow-import", name]) == 0
    monkeypatch.delitem(sys.modules, name)


# ---------------------------------------------------------------- resources

def test_a_spec_cannot_make_a_run_use_more_workers_than_the_machine_has(tmp_path, capsys, caplog):
    import numpy as np

    from tofnet.api import load_network
    from tofnet.events import make_events
    spec = tmp_path / "many.yaml"
    spec.write_text("processes:\n  input: {type: InputProcess, sensor_size: [10, 8]}\n"
                    "backend: {name: multiproc, workers: 24000, timeout: 5}\n")
    assert load_spec(spec).backend_options["workers"] == 24000  # the spec says what it says (round trip)
    with caplog.at_level(logging.WARNING, logger="tofnet"):
        options = load_network(spec)[3]
    assert options == {"workers": trust.cpu_count(), "timeout": 5}  # what the backend is built with
    assert [r.getMessage() for r in caplog.records] == [f"warning: {spec}: backend.workers: 24000 workers capped "
                                                        f"to this machine's {trust.cpu_count()} CPUs"]
    caplog.clear()
    spec.write_text(spec.read_text().replace("24000", "1"))
    with caplog.at_level(logging.WARNING, logger="tofnet"):
        assert load_network(spec)[3]["workers"] == 1
    assert not caplog.records
    spec.write_text(spec.read_text().replace("workers: 1", "workers: 24000"))
    np.save(tmp_path / "a.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 0]))
    (tmp_path / "plan.yaml").write_text("recordings: [a.npy]\nnetworks: [many.yaml]\ngrid: {refractory: [20ms]}\n")
    assert main(["batch", str(tmp_path / "plan.yaml"), "--check"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err and set(err) == {f"tofnet batch: warning: {spec}: backend.workers: 24000 workers capped to this "
                                f"machine's {trust.cpu_count()} CPUs"}
