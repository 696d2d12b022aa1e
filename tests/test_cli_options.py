"""Options a user can get wrong: each is one line naming the option (or one warning line), never
silently accepted (issue 25 item 5's review: --allow-import, --workers, --start, chunk_steps, camera)."""

import logging

import numpy as np
import pytest

from tofnet.backends.multiproc import MAX_CHUNK_STEPS, MultiprocBackend
from tofnet.batch import PlanError, load_plan
from tofnet.cli import main
from tofnet.cli.run import workers_option
from tofnet.errors import BackendError
from tofnet.io.trust import ENV_ALLOW_IMPORT, cpu_count
from tofnet.io.window import parse_window
from tofnet.testing import moving_pattern

SENSOR = (24, 16)
COMMON = ["--velocity", "0.5,0,0", "--intrinsics", "200,200,12,8", "--quiet"]


@pytest.fixture
def events_file(tmp_path):
    path = tmp_path / "ev.npy"
    np.save(path, moving_pattern(SENSOR, (300, -150), 50_000, seed=1))
    return path


def error_line(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_allow_import_names_a_module_that_exists(events_file, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(ENV_ALLOW_IMPORT, "not_installed_here")  # the standing list is not checked here
    out = str(tmp_path / "d.npz")
    for bad, why in (("nosuchmod_zz", "no module 'nosuchmod_zz' on the Python path"),
                     ("json.nosuch_zz", "no module 'json.nosuch_zz' on the Python path"),
                     ("../evil", "expected a module name such as my_package.my_module"),
                     ("", "expected a module name")):
        with pytest.raises(SystemExit) as exit_:
            main(["run", str(events_file), "--out", out, "--allow-import", bad, *COMMON])
        assert exit_.value.code == 2
        line = error_line(capsys)
        assert line.startswith("tofnet run: error: argument --allow-import: ") and why in line, line
    assert main(["run", str(events_file), "--out", out, "--allow-import", "json, tofnet.testing",
                 "--allow-import", "xml.etree", *COMMON]) == 0


class _EditableFinder:
    """What an editable install (setuptools >= 64, ``editables``) puts on ``sys.meta_path``: a top-level
    name mapped to a project folder, which is not on ``sys.path``."""

    def __init__(self, name: str, folder):
        self.name, self.folder = name, folder

    def find_spec(self, fullname, path=None, target=None):
        import importlib.util
        if fullname != self.name:
            return None
        package = self.folder / fullname
        return importlib.util.spec_from_file_location(fullname, package / "__init__.py",
                                                      submodule_search_locations=[str(package)])


def test_allow_import_finds_a_module_of_an_editable_install(events_file, tmp_path, monkeypatch):
    import sys
    from tofnet.io.trust import module_findable
    package = tmp_path / "project" / "tofnet_editable_zz"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("raise SystemExit('imported')\n")  # must not run
    (package / "procs.py").write_text("")
    monkeypatch.setattr(sys, "meta_path", [*sys.meta_path, _EditableFinder("tofnet_editable_zz", tmp_path / "project")])
    assert module_findable("tofnet_editable_zz") and module_findable("tofnet_editable_zz.procs")
    assert not module_findable("tofnet_editable_zz.nosuch") and "tofnet_editable_zz" not in sys.modules
    out = str(tmp_path / "d.npz")
    assert main(["run", str(events_file), "--out", out, "--allow-import", "tofnet_editable_zz.procs", *COMMON]) == 0


def test_more_workers_than_cpus_is_said_once(events_file, tmp_path, capsys, caplog):
    many = cpu_count() + 5
    with caplog.at_level(logging.WARNING, logger="tofnet"):
        assert workers_option(str(many)) == many  # the bands asked for, on the CPUs there are
        assert workers_option(str(cpu_count())) == cpu_count() and workers_option("auto") == "auto"
    assert [r.getMessage() for r in caplog.records] == [
        f"warning: --workers: {many} workers on this machine's {cpu_count()} CPUs: at most {cpu_count()} run at once"]
    capsys.readouterr()
    assert main(["run", str(events_file), "--out", str(tmp_path / "d.npz"), "--workers", str(many), *COMMON]) == 0
    err = capsys.readouterr().err.splitlines()
    assert [line for line in err if "--workers" in line] == [f"tofnet run: warning: --workers: {many} workers on "
                                                             f"this machine's {cpu_count()} CPUs: at most "
                                                             f"{cpu_count()} run at once"]


def test_a_time_before_the_first_event_is_refused(events_file, capsys):
    for option in ("--start=-1", "--until=-0.5s", "--start=-1ms"):
        assert main(["info", str(events_file), option]) == 2
        name = option.split("=")[0]
        assert error_line(capsys).startswith(f"tofnet info: error: {name}: -")
    assert parse_window("@-1s").start.us == -1_000_000  # a file's own clock may be negative
    assert parse_window("0", "1s").start.us == 0


def test_multiproc_chunk_steps_is_bounded():
    assert MultiprocBackend(workers=1, chunk_steps=MAX_CHUNK_STEPS).chunk_steps == MAX_CHUNK_STEPS
    for bad in (MAX_CHUNK_STEPS + 1, 10**18, 0, 2.5):
        with pytest.raises(BackendError, match="multiproc: chunk_steps must be") as err:
            MultiprocBackend(workers=1, chunk_steps=bad)
        assert "\n" not in str(err.value)


def test_a_plans_camera_key_gets_the_one_camera_check(events_file, tmp_path):
    (tmp_path / "calib.txt").write_text("200 200 12 8\n")
    plan = tmp_path / "plan.yaml"
    for text, where in (("recordings:\n  - {path: ev.npy, calib: calib.txt, camera: cam1}\n",
                         "2: recordings[0].camera"),
                        ("recordings: [ev.npy]\ncalib: calib.txt\ncamera: cam1\n", "3: camera")):
        plan.write_text(text)
        with pytest.raises(PlanError) as err:
            load_plan(plan)
        assert str(err.value) == (f"{plan}:{where}: cam1: {tmp_path / 'calib.txt'} holds one camera (calib.txt); "
                                  "camera picks one of a file with several")
    plan.write_text("recordings:\n  - {path: ev.npy, calib: calib.txt}\n")
    assert load_plan(plan)


def test_set_changes_one_parameter_of_the_chosen_network(events_file, tmp_path, capsys):
    """``--set PROCESS.PARAM=VALUE``: the value as a spec reads it; it changes what runs."""
    import json

    runs = {}
    for name, extra in (("default", []), ("distance 2", ["--set", "time_of_travel.distance=2"]),
                        ("refractory", ["--set", "input.refractory=20ms"])):
        out, summary = tmp_path / f"{len(runs)}.npz", tmp_path / f"{len(runs)}.json"
        assert main(["run", str(events_file), "--out", str(out), "--json", str(summary), *COMMON, *extra]) == 0
        runs[name] = json.loads(summary.read_text())
    assert runs["distance 2"]["depth_out"] != runs["default"]["depth_out"]
    assert runs["refractory"]["dropped"] != runs["default"]["dropped"]  # the input filter drops more
    capsys.readouterr()
    out = str(tmp_path / "bad.npz")
    for bad, why in (("time_surface.burst_surfaces=4", "has no process 'time_surface'; processes: input"),
                     ("input.refractory=banana", "input.refractory"),
                     ("time_of_travel.nosuch=1", "has no parameter 'nosuch'; expected"),
                     ("time_of_travel.distance", "expected PROCESS.PARAM=VALUE"),
                     ("nosuch.param=", "expected PROCESS.PARAM=VALUE"),
                     ("time_of_travel.distance=null", "time_of_travel.distance: a value is required")):
        assert main(["run", str(events_file), "--out", out, *COMMON, "--set", bad]) != 0
        line = error_line(capsys)
        assert line.startswith("tofnet run: error: --set ") and why in line, line


def test_a_recording_without_poses_says_how_to_give_the_velocity(tmp_path, capsys):
    """The default network reads the velocity from the poses; without them the line names the options."""
    from tofnet.events import make_events
    np.save(tmp_path / "ev.npy", make_events([0, 1000, 2000], [1, 2, 3], [1, 1, 1], [1, 1, 1]))
    assert main(["run", str(tmp_path / "ev.npy"), "--intrinsics", "200,200,120,90", "--out",
                 str(tmp_path / "d.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pass --velocity VX,VY,VZ" in err and "--set velocity.samples=FILE" in err
    assert main(["run", str(tmp_path / "ev.npy"), "--intrinsics", "200,200,120,90", "--velocity", "0.5,0,0",
                 "--out", str(tmp_path / "d.npz"), "--quiet"]) == 0


def test_the_hints_set_options_work_in_the_order_it_gives_them(tmp_path, capsys):
    """The options of one process are set together and checked once: the hint's order (source, then the
    samples it needs) works; a bad value among them is named and changes nothing (all or none)."""
    import re

    from tofnet.api import default_network
    from tofnet.errors import NetworkError
    from tofnet.events import make_events
    np.save(tmp_path / "ev.npy", make_events([0, 1000, 2000], [1, 2, 3], [1, 1, 1], [1, 1, 1]))
    (tmp_path / "vs.txt").write_text("0 0.5 0 0\n1 0.5 0 0\n")
    run = ["run", str(tmp_path / "ev.npy"), "--intrinsics", "200,200,120,90", "--out", str(tmp_path / "d.npz"),
           "--quiet"]
    assert main(run) == 2
    hint = re.search(r"--set (\S+=samples) --set (\S+)=FILE", capsys.readouterr().err)
    assert main([*run, "--set", hint[1], "--set", f"{hint[2]}={tmp_path / 'vs.txt'}"]) == 0
    assert main([*run, "--force", "--set", hint[1], "--set", "velocity.update_every=0",
                 "--set", f"{hint[2]}={tmp_path / 'vs.txt'}"]) == 2
    assert error_line(capsys) == ("tofnet run: error: --set velocity.update_every=0: velocity.update_every: "
                                  "expected at least 1 steps, got 0")
    velocity = default_network(sensor_size=(24, 16)).process("velocity")
    before = velocity.values
    with pytest.raises(NetworkError, match="source 'samples' needs samples"):
        velocity.set_params({"source": "samples", "per": "pixel"})
    assert velocity.values == before


def test_every_command_that_writes_takes_o_for_out():
    from tofnet.cli import build_parser

    parser = build_parser()
    for argv in (["run", "rec.raw"], ["batch", "plan.yaml"], ["demo"], ["live", "--replay", "rec.raw"],
                 ["plot", "depthmap", "rec", "depth.npz"]):
        short, long = parser.parse_args([*argv, "-o", "x"]), parser.parse_args([*argv, "--out", "x"])
        assert short.out == long.out == "x", argv


def test_a_bare_event_file_names_both_missing_camera_facts_at_once(tmp_path, capsys):
    from tofnet.events import make_events
    from tofnet.io.events import write_events_npy

    write_events_npy(tmp_path / "ev.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 0]))
    assert main(["run", str(tmp_path / "ev.npy"), "--out", str(tmp_path / "d.npz"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--velocity" in err[0] and "also pass --intrinsics" in err[0], err
    assert main(["run", str(tmp_path / "ev.npy"), "--out", str(tmp_path / "d.npz"), "--quiet",
                 "--intrinsics", "200,200,120,90"]) == 2
    err = capsys.readouterr().err
    assert "--velocity" in err and "also pass --intrinsics" not in err  # only what is still missing


def test_an_unknown_option_is_said_by_its_subcommand_with_the_closest_option(capsys):
    with pytest.raises(SystemExit) as code:
        main(["run", "rec", "--duraton", "1s"])
    assert code.value.code == 2
    assert error_line(capsys) == ("tofnet run: error: unrecognized arguments: --duraton 1s; did you mean --duration? "
                                  "(see 'tofnet run --help')")
    with pytest.raises(SystemExit):
        main(["info", "rec", "--qiet=1", "--nothing-like-it"])
    assert error_line(capsys) == ("tofnet info: error: unrecognized arguments: --qiet=1 --nothing-like-it; did you "
                                  "mean --quiet? (see 'tofnet info --help')")
    with pytest.raises(SystemExit):  # nothing close: no guess
        main(["convert", "a", "b", "--xyzzy", "extra"])
    assert error_line(capsys) == "tofnet convert: error: unrecognized arguments: --xyzzy extra (see 'tofnet convert --help')"


def test_the_workers_line_says_bands_and_threads_apart():
    from tofnet.cli.run_summary import workers_line

    assert workers_line({"threads": 2, "bands": 64, "whole": []}) == "64 bands of rows on 2 threads"
    assert workers_line({"threads": 1, "bands": 1, "whole": [], "one_band": "small packets"}) == \
        "1 band of rows on 1 thread; one band: small packets"
    assert workers_line({"threads": 2, "bands": 2, "whole": ["input", "velocity"], "unit": "threads"}) == \
        "2 bands of rows on 2 threads; run whole: input, velocity"
    assert workers_line({"threads": 1, "bands": 1, "whole": ["time_surface"], "unit": "processes"}) == \
        "1 band of rows on 1 process; run whole: time_surface"


def test_a_value_that_starts_with_a_minus_is_the_options_value(tmp_path, capsys):
    """``--velocity -0.5,0,0`` is a velocity (argparse alone reads ``-0.5,0,0`` as an option and says
    ``--velocity`` expected one argument); ``--start -1s`` gets the window's own error."""
    from tofnet.testing import moving_pattern

    recording = tmp_path / "rec.npy"
    np.save(recording, moving_pattern((64, 48), (-100.0, 0.0), 200_000))
    camera = ["--intrinsics", "200,200,32,24", "--sensor-size", "64x48", "--quiet"]
    assert main(["run", str(recording), "--velocity", "-0.5,0,0", *camera, "--out", str(tmp_path / "a.npz")]) == 0
    assert main(["run", str(recording), "--velocity=-0.5,0,0", *camera, "--out", str(tmp_path / "b.npz")]) == 0
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    capsys.readouterr()
    assert main(["run", str(recording), "--start", "-1s", *camera]) == 2
    assert "--start: -1 s is before the first event" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exited:  # a flag takes no value: still refused, by argparse
        main(["run", str(recording), "--quiet", "-1"])
    assert exited.value.code == 2 and "unrecognized arguments: -1" in capsys.readouterr().err


def test_a_velocity_without_translation_is_said_beside_the_empty_depth(tmp_path, capsys):
    from tofnet.testing import moving_pattern

    np.save(tmp_path / "rec.npy", moving_pattern((64, 48), (-100.0, 0.0), 200_000))
    argv = ["run", str(tmp_path / "rec.npy"), "--intrinsics", "200,200,32,24", "--sensor-size", "64x48"]
    assert main([*argv, "--velocity", "0,0,0", "--out", str(tmp_path / "zero.npz")]) == 0
    out = capsys.readouterr().out
    assert "depth out                 0" in out and "note           --velocity 0,0,0: no translation, so no depth" in out
    assert main([*argv, "--velocity", "0.5,0,0", "--out", str(tmp_path / "moving.npz")]) == 0
    assert "no translation" not in capsys.readouterr().out


def test_ctrl_c_inside_a_compiled_kernel_is_an_interruption_not_a_traceback(monkeypatch, capsys):
    """numba's dispatcher can wrap a KeyboardInterrupt in a SystemError ('returned a result with an exception
    set'): the command says it was interrupted and exits 130; any other SystemError is not swallowed."""
    import tofnet.cli.info

    def interrupted(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as err:
            raise SystemError("CPUDispatcher(<function k>) returned a result with an exception set") from err
    monkeypatch.setattr(tofnet.cli.info, "handle", interrupted)
    assert main(["info", "whatever"]) == 130
    assert capsys.readouterr().err.strip() == "tofnet info: interrupted"

    def broken(args):
        raise SystemError("a real bug")
    monkeypatch.setattr(tofnet.cli.info, "handle", broken)
    with pytest.raises(SystemError, match="a real bug"):
        main(["info", "whatever"])


def test_a_command_leaves_tofnets_log_as_it_found_it(tmp_path, capsys):
    """main() shows the log as 'tofnet COMMAND: ...' while the command runs; a script that calls the
    API afterwards must not see its warnings under that command's name (nor lose them to it)."""
    logger = logging.getLogger("tofnet")
    before = list(logger.handlers), logger.level, logger.propagate
    assert main(["info", str(tmp_path / "nothing.npy")]) == 2
    assert capsys.readouterr().err.startswith("tofnet info: error: ")
    assert (list(logger.handlers), logger.level, logger.propagate) == before
    logging.getLogger("tofnet.io.trust").warning("warning: after the command")
    assert "tofnet info" not in capsys.readouterr().err


@pytest.mark.parametrize("words, said", [
    (["live", "--replay", "EVENTS", "--seconds", "-5"], "--seconds: expected a time longer than 0 s, got -5"),
    (["live", "--replay", "EVENTS", "--seconds", "0"], "--seconds: expected a time longer than 0 s, got 0"),
    (["run", "EVENTS", "--timestep", "1ns"], "--timestep: input.timestep: expected at least 1e-06 s, got '1ns'"),
    (["run", "EVENTS", "--timestep", "1.5us"], "input.timestep: must be a whole number of microseconds, got 1.5 µs"),
])
def test_a_duration_the_clock_cannot_keep_is_one_line(events_file, tmp_path, capsys, words, said):
    """The clock counts whole µs: a step under 1 µs is refused by the parameter's bound, not by a second check
    that contradicts it; a wall-time limit of 0 or less would stop a live run after its first packet."""
    args = [str(events_file) if word == "EVENTS" else word for word in words]
    try:  # argparse's errors exit, tofnet's return
        run = words[0] == "run"  # (live has no --quiet)
        code = main([*args, "--out", str(tmp_path / ("d.npz" if run else "frames")), *(COMMON if run else COMMON[:-1])])
    except SystemExit as exit_:
        code = exit_.code
    assert code == 2 and said in error_line(capsys)


def test_a_sensor_size_other_than_the_files_is_said(tmp_path, capsys):
    """The file states 240x180: a smaller --sensor-size is a crop (the events outside counted, and said why), a
    larger one runs as given; info with one shows it over the file's, not in its place."""
    folder = tmp_path / "rec"
    assert main(["simulate", "slider", str(folder), "--duration", "0.03", "--quiet"]) == 0
    assert main(["run", str(folder), "--sensor-size", "120x90", "-o", str(tmp_path / "d.npz")]) == 0
    out = capsys.readouterr().out
    assert ("note           the file states a 240x180 px sensor; --sensor-size 120x90 runs 120x90 px of it (a crop: "
            "the events outside are counted out_of_bounds)") in out
    assert "events lay outside the 120x90 sensor (a crop of the file's, see the note)" in out
    assert main(["run", str(folder), "--sensor-size", "300x200", "-o", str(tmp_path / "e.npz")]) == 0
    assert "--sensor-size 300x200 runs 300x200 px (events read up to it)" in capsys.readouterr().out
    assert main(["run", str(folder), "-o", str(tmp_path / "f.npz")]) == 0
    assert "the file states" not in capsys.readouterr().out  # the file's own size: nothing to say
    assert main(["info", str(folder), "--sensor-size", "120x90"]) == 0
    out = capsys.readouterr().out
    assert "sensor         120x90 px" in out and "sensor size 120x90 px given, over the 240x180 px the file states" in out


def test_the_cloud_of_a_run_at_a_constant_velocity_takes_the_runs_camera_and_poses(events_file, tmp_path, capsys):
    """An event file with no calibration or poses, run with --intrinsics and --velocity: the depth file records
    both, and `plot cloud` places the estimates with them (it refused: no intrinsics, no poses)."""
    depth = tmp_path / "d.npz"
    assert main(["run", str(events_file), "-o", str(depth), *COMMON]) == 0
    capsys.readouterr()
    assert main(["plot", "cloud", str(events_file), str(depth), "--out", str(tmp_path / "c.png")]) == 0
    err = capsys.readouterr().err
    assert f"camera: the run's, from {depth} (fx 200, fy 200 px)" in err
    assert f"poses: the run's constant velocity (0.5, 0, 0 m/s, camera frame), from {depth}" in err
    assert (tmp_path / "c.png").stat().st_size > 10_000
