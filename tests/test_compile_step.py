"""The compile step is visible and apart: numba's first compile is announced on stderr (never stdout),
counted by ``Stopwatch`` and kept out of the network's time; ``tofnet warmup`` runs registered warmers."""

import logging
import time

import pytest
from numba import njit

from tofnet.cli import main
from tofnet.errors import TofnetError
from tofnet.kernels import compilation
from tofnet.kernels.compilation import COMPILING, Stopwatch
from tofnet.warmup import WARMERS, register_warmer, warm_up


def fresh_kernel():
    """A kernel numba has never seen (no cache): calling it compiles."""
    @njit(cache=False)
    def add_one(x):
        return x + 1
    return add_one


def test_stopwatch_counts_a_compile_and_keeps_it_out_of_the_network_time():
    kernel = fresh_kernel()
    clock = Stopwatch()
    assert kernel(1) == 2
    assert clock.compiled == 1 and clock.compile_seconds > 0
    compiled, seconds = clock.compiled, clock.compile_seconds
    time.sleep(0.05)
    kernel(2)  # compiled now: no new compile
    assert clock.compiled == compiled and clock.compile_seconds == seconds
    elapsed = time.perf_counter() - clock.started
    assert clock.network_seconds() == pytest.approx(elapsed - seconds, abs=0.02)
    assert clock.network_seconds() >= 0.05 - 0.01


def test_stopwatch_sets_set_up_aside_from_the_network_time_but_not_a_compile_within_it():
    kernel = fresh_kernel()
    clock = Stopwatch()
    with clock.aside():
        time.sleep(0.05)
        assert kernel(1) == 2  # a compile during set-up is still a compile
    time.sleep(0.02)
    assert clock.compiled == 1
    assert 0.05 - 0.005 <= clock.setup_seconds < 0.05 + clock.compile_seconds
    assert clock.network_seconds() == pytest.approx(
        time.perf_counter() - clock.started - clock.compile_seconds - clock.setup_seconds, abs=0.01)
    assert 0.02 - 0.005 <= clock.network_seconds() < 0.05


def test_building_the_bands_is_set_up_not_the_networks_time(monkeypatch):
    """With workers the bands' state is built for the first packet: the run reports it apart (as one
    worker's state, built when the stream opens), so the network's time compares across workers."""
    from tofnet.api import run
    from tofnet.backends.bands import BandedKernel
    from tofnet.io.recording import Recording
    from tofnet.networks import depth_network, improved_network
    from tofnet.testing import TEST_INTRINSICS, moving_edge

    build = BandedKernel._build

    def slow_build(self, packet):
        time.sleep(0.2)
        build(self, packet)

    monkeypatch.setattr(BandedKernel, "_build", slow_build)
    recording = Recording(moving_edge((16, 12), -50.0, "u"), intrinsics=TEST_INTRINSICS)
    velocity = {"source": "constant", "velocity": [-0.1, 0.0, 0.0]}
    result, _ = run(recording, depth_network((16, 12), velocity=velocity), backend_options={"workers": 2})
    assert result.extra["workers"] == 2
    assert result.setup_time >= 0.2 > result.wall_time
    summary = result.summary()
    assert summary["setup_time_s"] == result.setup_time
    assert "setup_time_s" not in result.facts()
    graph, _ = run(recording, improved_network((16, 12), velocity=velocity))  # model by model: its models' state
    assert graph.setup_time > 0


def test_first_compile_of_a_process_is_logged_once(caplog):
    compilation._said.clear()
    with caplog.at_level(logging.INFO, logger="tofnet.kernels"):
        fresh_kernel()(1)
        fresh_kernel()(1)
    said = [r.getMessage() for r in caplog.records if r.name == "tofnet.kernels"]
    assert said == [COMPILING]


def test_warmup_command_reports_each_warmer_and_says_its_own_wait(capsys):
    """warmup says its wait once, on stdout with its report (1-3 min for every kernel), not a run's
    'compiling kernels (20-60 s)' line."""
    compilation._said.clear()
    register_warmer("test-probe", lambda: fresh_kernel()(1) and "one fresh kernel")
    try:
        assert main(["warmup", "test-probe"]) == 0
    finally:
        del WARMERS["test-probe"]
    out, err = capsys.readouterr()
    assert "compiling kernels" not in err + out
    assert out.startswith("warming up every kernel tofnet runs (1-3 min on a fresh install")
    line = next(line for line in out.splitlines() if line.startswith("test-probe"))
    assert "1 kernel compiled" in line and "one fresh kernel" in line
    assert "done in" in out.splitlines()[-1]


def test_warm_up_refuses_an_unknown_warmer():
    with pytest.raises(TofnetError, match="unknown warmer 'nope'; expected one of backends"):
        warm_up(["nope"])


def test_run_summary_keeps_compile_time_apart_and_out_of_the_depth_file_facts():
    from tofnet.api import run
    from tofnet.io.recording import Recording
    from tofnet.networks import depth_network
    from tofnet.testing import TEST_INTRINSICS, moving_edge

    recording = Recording(moving_edge((16, 12), -50.0, "u"), intrinsics=TEST_INTRINSICS)
    network = depth_network((16, 12), velocity={"source": "constant", "velocity": [-0.1, 0.0, 0.0]})
    result, _ = run(recording, network)
    summary = result.summary()
    assert summary["compile_time_s"] == result.compile_time >= 0
    assert summary["kernels_compiled"] == result.kernels_compiled
    assert not {"compile_time_s", "kernels_compiled", "wall_time_s"} & set(result.facts())


@pytest.mark.slow
def test_a_first_run_on_a_fresh_install_says_it_compiles_and_reports_the_networks_speed(tmp_path):
    """``tofnet run`` with an empty numba cache (a fresh install), its output piped: the compile is
    announced on stderr as it starts, and the summary gives it apart, with the rate over the network's
    time only."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    from tofnet.io.ecd import write_ecd
    from tofnet.testing import TEST_INTRINSICS, moving_edge

    write_ecd(tmp_path / "rec", moving_edge((16, 12), -50.0, "u"), intrinsics=TEST_INTRINSICS)
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root), "NUMBA_CACHE_DIR": str(tmp_path / "fresh-cache")}
    done = subprocess.run([sys.executable, "-m", "tofnet", "run", "rec", "--velocity=-0.1,0,0", "--json", "summary.json"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "tofnet run: compiling kernels, first run only" in done.stderr.splitlines()[0]
    assert "compiling kernels" not in done.stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["kernels_compiled"] > 0 and summary["compile_time_s"] > 1.0
    assert summary["wall_time_s"] + summary["compile_time_s"] <= summary["total_time_s"]
    compile_line = next(line for line in done.stdout.splitlines() if line.startswith("compile "))
    assert f"{summary['kernels_compiled']} kernels compiled, not counted in the network's time" in compile_line
    wall = next(line for line in done.stdout.splitlines() if line.startswith("wall time"))
    rate = summary["events_in"] / summary["wall_time_s"] / 1e6  # events over the network's time only
    assert f"{summary['wall_time_s']:.3f} s network ({rate:.2f} M events/s)" in wall


def test_threads_compiling_at_once_count_their_overlap_once():
    """Bands compile (or wait for numba's lock) in several threads at once: the time not spent running
    is the union of their intervals, never more than the wall time (a first run with 2 workers said
    19.8 s of compiling in an 11.6 s run, and 0.000 s for the network)."""
    import threading

    from tofnet.kernels.compilation import _Watch

    watch = _Watch()
    inside = threading.Barrier(2)

    def compiling():
        watch.on_start(None)
        watch.on_start(None)  # numba nests its events: only the outermost counts
        inside.wait()
        time.sleep(0.2)
        watch.on_end(None)
        watch.on_end(None)

    begun = time.perf_counter()
    threads = [threading.Thread(target=compiling) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    wall = time.perf_counter() - begun
    assert watch.count == 2
    assert 0.2 <= watch.seconds <= wall


def test_warmup_tells_a_kernel_picking_number_from_other_numbers():
    """``tofnet warmup`` runs one conformance case per code path: a parameter declared ``selects_code``
    (burst_surfaces: another compiled kernel) makes its own path, other numbers do not."""
    from tofnet.conformance import get_case
    from tofnet.warmup import _code_path

    texture, one = (_code_path(get_case(name).build()) for name in ("time-surface-texture", "time-surface-one-surface"))
    assert texture != one
    assert _code_path(get_case("patch-d1").build()) == _code_path(get_case("patch-d2").build())
