"""``tofnet compile`` end to end, and every example spec."""

from __future__ import annotations

import json
import runpy
import sys
from pathlib import Path

import pytest

from tofnet.cli import main
from tofnet.io.compiled import compiled_from_dict
from tofnet.io.spec import dump_spec, load_spec, networks_equal

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("*.yaml"))


def test_compile_the_paper_example_prints_96(capsys):
    assert main(["compile", str(ROOT / "examples" / "paper_240x180.yaml")]) == 0
    out = capsys.readouterr().out
    assert "48 + 48 = 96 on 1 chip" in out
    assert "time_of_travel  TimeOfTravelProcess  30x30  8x6      48  7200/8192 (87.9%)" in out
    assert "host      input (InputProcess), velocity (VelocityProcess)" in out


def test_compile_auto_and_a_larger_sensor(capsys):
    assert main(["compile", "--patch", "auto"]) == 0  # the built-in default spec
    assert "44 + 32 = 76 on 1 chip" in capsys.readouterr().out
    assert main(["compile", "--sensor-size", "1280x720"]) == 0
    assert "1032 + 1032 = 2064 on 17 chips" in capsys.readouterr().out
    assert main(["compile", "--patch", "30x30", "--patch", "depth=auto"]) == 0
    assert "48 + 32 = 80 on 1 chip" in capsys.readouterr().out


def test_compile_json_round_trips(tmp_path, capsys):
    out = tmp_path / "compiled.json"
    assert main(["compile", str(ROOT / "examples" / "paper_distance2.yaml"), "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    compiled = compiled_from_dict(data)
    assert compiled.cores_used == 96 and compiled.network.process("time_of_travel").distance == 2
    assert compiled.cores[0].halo == ((0, 0, 32, 30), (0, 0, 30, 32))


def test_compile_errors_are_one_line(tmp_path, capsys):
    assert main(["compile", "--sensor-size", "346x260", "--budget", "oheo-gulch", "--patch", "30x30"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tofnet compile: error: network 'paper-240x180' needs 216 cores") and "max_chips: 2" in err
    assert len(err.strip().splitlines()) == 1
    budget = tmp_path / "budget.yaml"
    budget.write_text("core: {accumulators: 4096}\nmax_chips: 1\n")
    assert main(["compile", "--budget", str(budget), "--patch", "30x30"]) == 2
    assert "a 30x30 patch needs 7200 accumulators per core" in capsys.readouterr().err
    assert main(["compile", "--budget", str(budget), "--patch", "auto"]) == 2
    assert "allow max_chips: 2" in capsys.readouterr().err
    assert main(["compile", "--budget", str(budget), "--patch", "auto", "--max-chips", "2"]) == 0
    for chips in ("0", "1.5"):  # one message for both (1.5 was argparse's "invalid int value")
        assert main(["compile", "--max-chips", chips]) == 2
        assert f"--max-chips: expected a whole number of chips >= 1, got '{chips}'" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nprocesses:\n  input: {type: Camera}\n")
    assert main(["compile", str(bad)]) == 2
    assert f"{bad}:3: processes.input.type: unknown process type 'Camera'" in capsys.readouterr().err


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_loads_compiles_and_round_trips(path):
    spec = load_spec(path)
    compiled = spec.compile_network()
    on_cores = {p.name for p in spec.network.processes if p.placement != "host"}
    assert {c.process for c in compiled.cores} == on_cores  # every core process has cores (none: improved.yaml)
    assert set(compiled.host) == {p.name for p in spec.network.processes} - on_cores
    again = load_spec(dump_spec(spec))
    assert networks_equal(again.network, spec.network) and again.compile == spec.compile
    assert again.backend == spec.backend


def test_example_core_counts():
    counts = {p.name: load_spec(p).compile_network() for p in EXAMPLES}
    assert counts["paper_240x180.yaml"].cores_used == 96
    assert counts["paper_distance2.yaml"].cores_used == 96
    assert counts["half_resolution.yaml"].cores_used == 24
    small = counts["budget_small_core.yaml"]
    assert (small.cores_used, small.chips_used, small.budget.name) == (315, 5, "small-core")


def test_build_paper_network_example(capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["build_paper_network.py"])
    runpy.run_path(str(ROOT / "examples" / "build_paper_network.py"), run_name="__main__")
    assert "48 + 48 = 96 on 1 chip" in capsys.readouterr().out


def test_the_custom_process_example_runs_as_documented():
    import subprocess
    import sys
    done = subprocess.run([sys.executable, str(ROOT / "examples" / "custom_process.py"), "--duration", "0.08"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    out = done.stdout
    assert "consistent.kept" in out and "multiproc vs fixed (exact): same" in out
    assert "float vs reference (float): same" in out and "fixed vs reference (quantised): same" in out
