"""`tofnet batch` on a local Dask cluster (loopback, 2 workers).

Equal to `tofnet run` one by one, deterministic, failed rows, killed workers, resume, Ctrl-C.
"""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from optional import optional

optional("distributed")

from tofnet.batch import load_plan, run_batch  # noqa: E402
from tofnet.batch.runner import local_cluster  # noqa: E402
from tofnet.batch.table import TIMING_COLUMNS, read_csv  # noqa: E402
from tofnet.cli import main  # noqa: E402
from tofnet.eval.breakdown import BREAKDOWN_COLUMNS  # noqa: E402
from tofnet.io import read_depth  # noqa: E402

SCENARIOS = ["slider", "forward", "paper_all_axes"]  # desk x, desk z, room all axes
REFRACTORY = ["20ms", "40ms", "60ms", "100ms"]
SCENE = "duration: 0.1\n    sensor_size: 96x72"


@pytest.fixture(scope="module")
def client():
    from distributed import Client
    with local_cluster(2) as cluster, Client(cluster, set_as_default=False) as c:
        yield c


def test_the_local_cluster_takes_work_from_this_process_only_and_serves_no_pages(client):
    """Another user's process on the machine can reach loopback: without the certificates made for this cluster
    it cannot submit work (code run as the batch's user), and the HTTP server Dask starts answers no page."""
    import urllib.error
    import urllib.request

    from distributed.security import Security

    address = client.scheduler.address
    assert address.startswith("tls://127.0.0.1:")
    for attempt, security in ((address.replace("tls://", "tcp://"), None), (address, Security.temporary())):
        with pytest.raises(Exception):  # refused: encryption required / certificate not of this cluster
            Client(attempt, timeout="5s", security=security, set_as_default=False)
    port = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.http_server.port)
    host = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.http_server.address)
    assert host == "127.0.0.1"
    for page in ("info/main/workers.html", "json/identity.json", "health"):
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/{page}", timeout=5)
        assert refused.value.code == 404
    assert client.submit(sum, [1, 2]).result() == 3  # the batch's own client works


@pytest.fixture(scope="module")
def existing():
    """A client of a cluster a user started (plain TCP), which ``tofnet batch --scheduler`` connects to too."""
    import logging

    from distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None,
                      silence_logs=logging.CRITICAL) as cluster, Client(cluster, set_as_default=False) as c:
        yield c


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("scenarios")


def plan_file(folder, cache, recordings, grid, keep="[summary, metrics, depth]"):
    path = folder / "plan.yaml"
    path.write_text(f"name: test\noutput: out\ncache: {cache}\nrecordings:\n{recordings}\n"
                    f"grid:\n{grid}\nkeep: {keep}\n")
    return path


@pytest.fixture(scope="module")
def sweep(client, cache, tmp_path_factory):
    """The built-in scenarios x 4 refractory periods, run once for the tests below."""
    folder = tmp_path_factory.mktemp("sweep")
    path = plan_file(folder, cache, f"  - scenario: [{', '.join(SCENARIOS)}]\n    {SCENE}",
                     f"  refractory: [{', '.join(REFRACTORY)}]")
    return path, run_batch(load_plan(path), client=client)


def test_a_sweep_equals_the_same_runs_done_one_by_one_with_tofnet_run(sweep, tmp_path):
    _, result = sweep
    assert [r["status"] for r in result.rows] == ["ok"] * len(SCENARIOS) * len(REFRACTORY), result.rows[0]["error"]
    assert [(r["scenario"], r["refractory"]) for r in result.rows] == \
        [(s, v) for s in SCENARIOS for v in REFRACTORY]
    for row in result.rows:
        recording = json.loads(open(row["summary_file"]).read())["recording"]
        out, summary_file = tmp_path / "depth.npz", tmp_path / "run.json"
        assert main(["run", recording, "--refractory", row["refractory"], "--out", str(out), "--json",
                     str(summary_file), "--quiet", "--force"]) == 0
        alone = json.loads(summary_file.read_text())
        assert (row["events_in"], row["accepted"], row["dropped"], row["tot_spikes"], row["depth_out"]) == \
            (alone["events_in"], alone["accepted"], sum(alone["dropped"].values()), alone["tot_spikes"],
             alone["depth_out"])
        assert {r: row[f"dropped_{r}"] for r in alone["dropped"]} == alone["dropped"]
        assert {r: row[f"rejected_{r}"] for r in alone["rejected"]} == alone["rejected"]
        batch_depth, _ = read_depth(row["depth_file"])
        alone_depth, _ = read_depth(out)
        assert batch_depth.tobytes() == alone_depth.tobytes()
        assert row["depth_out"] > 0 and row["matched"] > 0 and 0 < row["median_rel_pct"] < 100
        scores_file = tmp_path / "scores.json"
        assert main(["eval", recording, str(out), "--json", str(scores_file), "--force"]) == 0
        scores = json.loads(scores_file.read_text())
        groups = scores["depth_bands"] + scores["motion_phases"]
        cover = [row[c] for c in BREAKDOWN_COLUMNS if c.startswith("coverage_")]
        assert cover == [None if g["coverage"] is None else pytest.approx(100 * g["coverage"]) for g in groups]
        assert any(c for c in cover)
    # the refractory period filters more the longer it is
    slider = [r["dropped_refractory"] for r in result.rows if r["scenario"] == "slider"]
    assert slider == sorted(slider) and slider[0] < slider[-1]


def test_the_same_plan_gives_the_same_table_apart_from_timing(sweep, client):
    path, first = sweep
    first_table = read_csv(first.files[0])
    second = run_batch(load_plan(path), client=client, force=True)  # not resumed: every task runs again
    assert second.resumed == 0
    second_table = read_csv(second.files[0])
    strip = [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in first_table]
    assert strip == [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in second_table]
    assert [int(r["task"]) for r in first_table] == list(range(len(first_table)))
    assert first.plot is not None and first.plot.stat().st_size > 10_000
    if len(first.files) > 1:  # Parquet when pyarrow is installed
        import pyarrow.parquet as pq
        table = pq.read_table(first.files[1]).to_pylist()
        assert [r["depth_out"] for r in table] == [int(r["depth_out"]) for r in first_table]


def test_a_failing_task_becomes_a_failed_row_and_the_batch_goes_on(client, cache, tmp_path):
    (tmp_path / "broken.npy").write_bytes(b"not an array")
    path = plan_file(tmp_path, cache, f"  - broken.npy\n  - scenario: slider\n    {SCENE}",
                     "  refractory: [20ms]")
    result = run_batch(load_plan(path), client=client)
    rows = {r["recording_name"]: r for r in result.rows}
    assert rows["slider"]["status"] == "ok"
    assert rows["broken"]["status"] == "failed" and "broken.npy" in rows["broken"]["error"]
    assert "\n" not in rows["broken"]["error"]
    assert len(result.failed) == sum(r["status"] == "failed" for r in result.rows)
    table = read_csv(result.files[0])
    assert [r["status"] for r in table] == [r["status"] for r in result.rows]


def test_a_killed_worker_is_replaced_and_its_task_rerun(client, cache, tmp_path):
    # a larger scene than the other tests': its simulation and runs keep a worker busy long enough to be killed
    path = plan_file(tmp_path, cache, "  - scenario: [slider]\n    duration: 0.1",
                     "  refractory: [5ms, 10ms, 20ms, 30ms, 40ms, 60ms]", keep="[summary]")
    pids = client.run(os.getpid)
    killed = []

    def kill_a_busy_worker(counts):
        if killed:
            return
        busy = [worker for worker, keys in client.processing().items() if keys]
        if busy:
            os.kill(pids[busy[0]], signal.SIGKILL)
            killed.append(busy[0])

    result = run_batch(load_plan(path), client=client, progress=kill_a_busy_worker)
    assert killed, "no worker was busy to be killed"
    assert [r["status"] for r in result.rows] == ["ok"] * 6
    client.wait_for_workers(2, timeout=30)
    assert killed[0] not in client.scheduler_info()["workers"]  # the nanny started a new worker process


def test_resume_runs_only_what_is_missing(client, cache, tmp_path):
    path = plan_file(tmp_path, cache, f"  - scenario: slider\n    {SCENE}", "  refractory: [20ms, 40ms, 60ms]")
    first = run_batch(load_plan(path), client=client)
    folders = [os.path.dirname(r["summary_file"]) for r in first.rows]
    # an interrupted task: no row.json, a half-written temp file, an old depth file
    os.remove(os.path.join(folders[1], "row.json"))
    open(os.path.join(folders[1], ".row.tmp-1-abc.json"), "w").write("{")
    # a task whose kept outputs are incomplete: its depth file is gone
    os.remove(os.path.join(folders[2], "depth.npz"))
    before = os.path.getmtime(os.path.join(folders[0], "row.json"))
    time.sleep(0.01)
    again = run_batch(load_plan(path), client=client, resume=True)
    assert again.resumed == 1 and [r["status"] for r in again.rows] == ["ok"] * 3
    assert os.path.getmtime(os.path.join(folders[0], "row.json")) == before
    assert os.path.exists(os.path.join(folders[2], "depth.npz"))
    assert again.rows[0]["worker"] == first.rows[0]["worker"]
    assert read_csv(again.files[0])[1]["depth_out"] == str(first.rows[1]["depth_out"])


def test_ctrl_c_stops_cleanly_and_resume_finishes_the_batch(existing, cache, tmp_path):
    client = existing
    path = plan_file(tmp_path, cache, f"  - scenario: [slider, vertical, diagonal]\n    {SCENE}",
                     "  refractory: [5ms, 10ms, 20ms, 40ms]", keep="[summary]")
    command = [sys.executable, "-m", "tofnet", "batch", str(path), "--scheduler", client.scheduler.address]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True,  # its own group, like a terminal's foreground job
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    tasks = tmp_path / "out" / "tasks"
    deadline = time.monotonic() + 60
    while not list(tasks.glob("*/row.json")) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)
    os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
    out, err = process.communicate(timeout=60)
    while any(client.processing().values()):  # a task running at Ctrl-C ends on its worker (Dask cannot stop it)
        time.sleep(0.05)
    done = len(list(tasks.glob("*/row.json")))
    if process.returncode == 0:
        pytest.skip("the batch finished before Ctrl-C reached it")
    assert process.returncode == 130 and "interrupted" in err and "--resume" in err
    assert "Traceback" not in err
    resumed = run_batch(load_plan(path), client=client, resume=True)
    assert resumed.resumed == done >= 1
    assert [r["status"] for r in resumed.rows] == ["ok"] * 12


def test_the_command_on_an_existing_scheduler_reports_progress_failures_and_files(existing, cache, tmp_path, capsys):
    client = existing
    (tmp_path / "broken.npy").write_bytes(b"not an array")
    path = plan_file(tmp_path, cache, f"  - broken.npy\n  - scenario: slider\n    {SCENE}", "  distance: [1, 2]",
                     keep="[metrics]")
    assert main(["batch", str(path), "--scheduler", client.scheduler.address]) == 1  # a task failed
    captured = capsys.readouterr()
    assert "tofnet batch: 4/4 done (2 failed)" in captured.err and "M events/s" in captured.err
    assert "4 tasks, 2 ok, 2 failed" in captured.out and "failed  broken.paper.distance=1-" in captured.out
    assert str(tmp_path / "out" / "results.csv") in captured.out and "plot.png" in captured.out


def test_a_task_whose_worker_kept_dying_becomes_a_failed_row(tmp_path):
    from tofnet.batch import expand
    from tofnet.batch.runner import _Execution

    class KilledWorker(Exception):
        pass

    class Future:
        status = "error"

        def exception(self):
            return KilledWorker("attempted to run task run-x on 3 different workers")

    task = expand(load_plan(f"recordings: [{{scenario: slider}}]\noutput: {tmp_path}\n"))[0]
    row = _Execution(None, [task], {}, None, 1).collect(Future(), task)
    assert row["status"] == "failed" and row["error"].startswith("KilledWorker: the worker died")
    assert json.loads((tmp_path / "tasks" / task.task_id / "row.json").read_text())["status"] == "failed"


def test_resume_runs_again_a_task_whose_recording_changed(client, cache, tmp_path):
    import numpy as np

    from tofnet.events import make_events

    np.save(tmp_path / "a.npy", make_events([0, 1000, 2000], [1, 2, 3], [1, 1, 1], [1, 1, 1]))
    path = plan_file(tmp_path, cache, '  - {path: a.npy, intrinsics: "200,200,120,90", velocity: [0.5, 0, 0]}',
                     "  refractory: [20ms]", keep="[summary]")
    first = run_batch(load_plan(path), client=client)
    assert first.rows[0]["status"] == "ok" and first.rows[0]["events_in"] == 3, first.rows[0]["error"]
    assert run_batch(load_plan(path), client=client, resume=True).resumed == 1
    np.save(tmp_path / "a.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 1]))  # same path, other content
    again = run_batch(load_plan(path), client=client, resume=True)
    assert again.resumed == 0 and again.rows[0]["events_in"] == 2
