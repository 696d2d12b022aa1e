"""The lava backend: tofnet graphs as Lava processes, byte for byte what the fixed backend computes.

Needs lava-nc 0.10 (Python 3.10): tests/test_lava_venv.py makes that venv when a Python 3.10 exists. Under
any other interpreter only the one-line refusal is checked.
"""

import importlib.util
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tofnet.backends.registry import available_backends, get_backend
from tofnet.cli import main
from tofnet.conformance import format_table, run_suite
from tofnet.conformance.cases import get_case
from tofnet.errors import BackendError, UnsupportedError
from tofnet.session import Session

LAVA = sys.version_info[:2] == (3, 10) and importlib.util.find_spec("lava") is not None
needs_lava = pytest.mark.skipif(not LAVA, reason="lava-nc 0.10 is not importable here (it needs Python 3.10)")

#: Cases that cover every kind of graph and port the suite has (the whole suite: `tofnet conformance
#: --backend lava --against fixed`, docs/lava.md): one chain, counter overflow, core seams, fan-out
#: and fan-in, a core-placed filter, a user's process, eq. 7, a host remap, variables through Var.get.
CASES = ["edge+u", "speed-4bit-16", "patch-d2-ragged", "graph-two-distances", "graph-denoised",
         "graph-user-process", "graph-undistort", "rotation-edges", "variables-update-every", "empty"]


@pytest.mark.skipif(LAVA, reason="checks the refusal where Lava cannot run; Lava runs here")
def test_without_lava_the_backend_says_in_one_line_what_it_needs(capsys):
    with pytest.raises(BackendError) as err:
        get_backend("lava")
    text = str(err.value)
    assert "\n" not in text and "Python 3.10" in text and "pip install 'tofnet[lava]'" in text
    assert main(["conformance", "--backend", "lava", "--case", "edge+u"]) != 0  # one line, not a table of failures
    assert capsys.readouterr().err.strip().splitlines() == [f"tofnet conformance: error: {text}"]


def test_lava_is_asked_for_by_name_and_not_listed_with_the_backends_every_install_runs():
    assert "lava" not in available_backends()
    assert "lava" in available_backends(optional=True)
    with pytest.raises(BackendError, match="arithmetic must be 'fixed' or 'float'"):
        get_backend("lava", arithmetic="double")


@needs_lava
def test_lava_runs_the_fixed_models_or_the_float_ones():
    assert get_backend("lava").family == "fixed" and get_backend("lava", arithmetic="float").family == "float"


@needs_lava
def test_lava_equals_the_fixed_backend_byte_for_byte():
    results = run_suite("lava", "fixed", CASES)
    assert [r.case for r in results] == CASES and {r.mode for r in results} == {"exact"}
    assert all(r.ok and r.applies for r in results), "\n" + format_table(results)
    assert sum(r.estimates[0] for r in results) > 1000  # the cases produce estimates, and they were compared


@needs_lava
def test_lava_floating_pt_equals_the_float_backend():
    (result,) = run_suite(get_backend("lava", arithmetic="float"), "float", ["texture-checker"])
    assert result.ok and result.mode == "float" and result.estimates[0] > 100, result.first


@needs_lava
def test_a_host_side_estimator_is_refused_in_one_line_naming_it_and_the_suite_calls_it_not_applicable():
    case = get_case("time-surface-texture").build()
    with pytest.raises(UnsupportedError) as err:
        get_backend("lava").run(case.network, case.recording)
    assert "\n" not in str(err.value) and "'time_surface' (TimeSurfaceProcess) cannot run in Lava" in str(err.value)
    (result,) = run_suite("lava", "fixed", ["time-surface-texture"])
    assert result.ok and not result.applies and result.first.startswith("n/a: ")


@needs_lava
def test_var_set_reaches_the_model_as_a_session_set_does_on_fixed():
    case = get_case("texture-blobs").build()
    runs = {}
    for name in ("fixed", "lava"):
        with Session(case.network, case.recording, backend=name, record_tot=True) as s:
            s.run(steps=20)
            counter = s.get("time_of_travel.counter")
            s.set("time_of_travel.counter", np.zeros_like(counter))  # Var.set on lava
            assert np.array_equal(s.get("time_of_travel.counter"), np.zeros_like(counter))
            runs[name] = (counter, s.finish())
    (c_fixed, fixed), (c_lava, lava) = runs["fixed"], runs["lava"]
    assert c_fixed.any() and np.array_equal(c_fixed, c_lava)
    assert fixed.counts == lava.counts and len(lava.depth) > 100
    assert fixed.depth.tobytes() == lava.depth.tobytes()


@needs_lava
def test_a_step_busier_than_the_source_holds_is_refused_naming_the_option():
    case = get_case("texture-blobs").build()
    with pytest.raises(BackendError, match="raise the backend's source_capacity"):
        get_backend("lava", source_capacity=2).run(case.network, case.recording)


@needs_lava
def test_a_model_failing_inside_lava_is_one_error_naming_the_process_not_a_hang(monkeypatch):
    import tofnet.backends.lava_backend as lava_backend

    monkeypatch.setattr(lava_backend, "FIELD_RECORDS", 0)  # the velocity's first update no longer fits its port
    case = get_case("edge+u").build()
    with pytest.raises(BackendError) as err:
        get_backend("lava").run(case.network, case.recording)
    assert str(err.value).startswith("lava backend: process 'velocity' failed in step 0: velocity.a_t: 1 records")


@needs_lava
def test_a_session_left_open_does_not_keep_the_interpreter_from_exiting():
    script = textwrap.dedent("""
        from tofnet.conformance.cases import get_case
        from tofnet.session import Session
        case = get_case("edge+u").build()
        session = Session(case.network, case.recording, backend="lava")
        session.run(steps=5)
        print("ran", session.step)
    """)  # never stopped: the runtime must still stop at exit (multiprocessing would wait for it)
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, cwd=root,
                          env={**os.environ, "PYTHONPATH": str(root)})
    assert done.returncode == 0 and done.stdout.strip() == "ran 5", done.stderr[-2000:]


@needs_lava
def test_the_command_line_runs_the_suite_on_lava_under_python_3_10():
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, "-m", "tofnet", "conformance", "--backend", "lava", "--against", "fixed",
                           "--case", "edge+u", "--case", "time-surface-texture"], capture_output=True, text=True,
                          timeout=300, cwd=root, env={**os.environ, "PYTHONPATH": str(root)})
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "2 cases: 1 passed, 1 not applicable, 0 failed (lava vs fixed" in done.stdout
