"""`tofnet batch` on a standalone Dask cluster: `dask scheduler` and two `dask worker` processes, each in its
own folder, with relative paths on the command line; and a worker without tofnet named in one line."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from optional import optional

optional("distributed")
if shutil.which("dask") is None:
    pytest.skip("needs the dask command: pip install \"tofnet[batch]\"", allow_module_level=True)

from tofnet.batch.table import TIMING_COLUMNS, read_csv  # noqa: E402
from tofnet.io import write_ecd  # noqa: E402

from formats_helpers import pattern_recording  # noqa: E402

ROOT = str(Path(__file__).resolve().parents[1])
START_S = 60  # at most, for the scheduler's file and the workers to appear


#: A `dask worker` on which tofnet cannot be imported, even where it is installed (CI pip-installs it):
#: a finder in front of the others answers as Python does for a package that is not there.
WORKER_WITHOUT_TOFNET = """
import sys
class NoTofnet:
    def find_spec(self, name, path=None, target=None):
        if name == "tofnet" or name.startswith("tofnet."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, NoTofnet())
from distributed.cli.dask_worker import main
main()
"""


def _start(args, cwd, log, pythonpath, command=("dask",)):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    env["PYTHONUNBUFFERED"] = "1"
    with open(log, "wb") as out:
        # A session of its own: the whole process group is ended at the end of the test.
        return subprocess.Popen([*command, *args], cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)


def _stop(processes):
    for process in processes:
        if process.poll() is None:
            try:
                os.killpg(process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    for process in processes:
        process.wait(timeout=30)


def _workers(address, n):
    from distributed import Client
    with Client(address, timeout="20s") as client:
        client.wait_for_workers(n, timeout=START_S)
        return sorted(client.scheduler_info()["workers"])


def _batch(cwd, *args):
    env = {**os.environ, "PYTHONPATH": ROOT}
    return subprocess.run([sys.executable, "-m", "tofnet", "batch", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def _table(path):
    return [{k: v for k, v in row.items() if k not in TIMING_COLUMNS + ("worker", "depth_file", "summary_file")}
            for row in read_csv(path)]


@pytest.mark.slow
def test_a_standalone_cluster_with_relative_paths_gives_the_local_table(tmp_path):
    recording = pattern_recording(150_000)
    client_dir = tmp_path / "client"
    data = client_dir / "data"
    data.mkdir(parents=True)
    write_ecd(data / "pattern", recording.events, intrinsics=recording.intrinsics,
              times=recording.trajectory.times, positions=recording.trajectory.positions,
              quaternions=recording.trajectory.quaternions, sensor_size=recording.sensor_size)
    (data / "plan.yaml").write_text("recordings: [pattern]\ngrid:\n  refractory: [20ms, 60ms]\n"
                                    "keep: [summary, metrics, depth]\nstart: 20ms\n")
    processes = []
    try:
        for name in ("scheduler", "worker-1", "worker-2", "bare-worker"):
            (tmp_path / name).mkdir()
        scheduler_file = tmp_path / "scheduler" / "scheduler.json"
        processes.append(_start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                 "--scheduler-file", str(scheduler_file)], tmp_path / "scheduler",
                                tmp_path / "scheduler.log", ROOT))
        deadline = time.monotonic() + START_S
        while not scheduler_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(scheduler_file.read_text())["address"]
        for name in ("worker-1", "worker-2"):
            processes.append(_start(["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                     "--name", name], tmp_path / name, tmp_path / f"{name}.log", ROOT))
        assert len(_workers(address, 2)) == 2

        # Relative plan and --out, from a folder the workers do not run in.
        remote = _batch(client_dir, "data/plan.yaml", "--scheduler", address, "--out", "remote", "--quiet")
        assert remote.returncode == 0, remote.stderr + remote.stdout
        local = _batch(client_dir, "data/plan.yaml", "--workers", "1", "--out", "local", "--quiet")
        assert local.returncode == 0, local.stderr + local.stdout
        rows = read_csv(client_dir / "remote" / "results.csv")
        assert len(rows) == 2 and {r["status"] for r in rows} == {"ok"}
        for row in rows:  # the files the table names exist, where the client sees them
            assert Path(row["depth_file"]).is_absolute() and Path(row["depth_file"]).is_file()
            assert str(client_dir / "remote") in row["depth_file"]
        assert _table(client_dir / "remote" / "results.csv") == _table(client_dir / "local" / "results.csv")
        for name in ("worker-1", "worker-2"):
            assert not list((tmp_path / name).rglob("*.npz"))  # nothing written in a worker's own folder

        # A worker that cannot import tofnet: one line naming it and the package, before any task.
        processes.append(_start([address, "--nthreads", "1", "--no-nanny", "--no-dashboard", "--name", "bare"],
                                tmp_path / "bare-worker", tmp_path / "bare.log", None,
                                command=(sys.executable, "-c", WORKER_WITHOUT_TOFNET)))
        assert len(_workers(address, 3)) == 3
        failed = _batch(client_dir, "data/plan.yaml", "--scheduler", address, "--out", "again", "--quiet")
        assert failed.returncode == 2
        lines = failed.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in failed.stderr, failed.stderr
        assert "cannot import tofnet (ModuleNotFoundError: No module named 'tofnet')" in lines[0]
        assert "the Dask worker tcp://127.0.0.1:" in lines[0]
    finally:
        _stop(processes)
