"""Compiling every kernel ahead (``tofnet warmup``), so that no run pays numba's first-call compile.

numba compiles a kernel the first time it is called with new argument types and caches the
machine code on disk (``tofnet.kernels.compilation``). A warmer is a function that calls some
kernels on tiny inputs through the code paths real runs take, so that numba compiles exactly
the signatures they need; ``register_warmer`` adds one (a new area of tofnet, or a user's
package with kernels of its own). The built-in warmers are generic: every conformance case
(which covers every built-in process and graph) on each backend family, the multiproc backend's
worker processes included, and every built-in simulator scenario for a few milliseconds through
the pipeline of ``tofnet demo`` (simulate, write, read, run each built-in estimator, score).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterable

from tofnet.errors import TofnetError

#: name -> warmer: a function that exercises some kernels and returns what it ran, in a few words.
WARMERS: dict[str, Callable[[], str]] = {}


def register_warmer(name: str, warm: Callable[[], str]) -> None:
    """Make ``warm()`` part of ``tofnet warmup`` as ``name`` (replacing a warmer of that name)."""
    WARMERS[name] = warm


@dataclass
class Warmed:
    """What one warmer did: what it ran, its seconds in all, the seconds spent compiling or loading
    kernels from numba's cache, and the kernels it compiled (0: all were in the cache)."""

    name: str
    what: str
    seconds: float
    compile_seconds: float
    compiled: int

    def line(self) -> str:
        from tofnet.kernels.compilation import kernels
        how = (f"{kernels(self.compiled)} compiled in {self.compile_seconds:.1f} s" if self.compiled
               else f"already compiled (cache loaded in {self.compile_seconds:.1f} s)")
        return f"{self.name:<12} {self.seconds:6.1f} s  {how}: {self.what}"


def check_names(names: Iterable[str] | None) -> list[str]:
    """The warmers called ``names`` (all when None); a one-line ``TofnetError`` names an unknown one."""
    chosen = list(WARMERS) if names is None else list(names)
    unknown = [name for name in chosen if name not in WARMERS]
    if unknown:
        raise TofnetError(f"unknown warmer {unknown[0]!r}; expected one of {', '.join(WARMERS)}")
    return chosen


def warm_up(names: Iterable[str] | None = None, report: Callable[[Warmed], None] | None = None) -> list[Warmed]:
    """Run the warmers called ``names`` (all when None), calling ``report`` after each; what each did."""
    from tofnet.kernels.compilation import Stopwatch

    chosen = check_names(names)
    done = []
    for name in chosen:
        clock = Stopwatch()
        what = WARMERS[name]()
        done.append(Warmed(name, what, time.perf_counter() - clock.started, clock.compile_seconds, clock.compiled))
        if report is not None:
            report(done[-1])
    return done


def _families_warmer(backends: tuple[str, ...]) -> Callable[[], str]:
    def warm() -> str:
        import contextlib

        from tofnet.backends.registry import get_backend
        from tofnet.compiler import compile_network
        from tofnet.conformance import CASES
        from tofnet.conformance.runner import BackendRunner
        from tofnet.errors import UnsupportedError

        scenes = {}
        for case in CASES:  # one case per code path: many differ only in numbers (speeds, sizes)
            scene = case.build()
            scenes.setdefault(_code_path(scene), scene)
        for backend in backends:
            with contextlib.ExitStack() as stack:  # as the conformance suite runs it (multiproc: one session)
                runner = BackendRunner(get_backend(backend), stack)
                for scene in scenes.values():
                    try:
                        runner.run(compile_network(scene.network, patch=scene.patch), scene.recording)
                    except UnsupportedError:
                        continue  # a graph this backend does not hold: nothing of it to compile
        return (f"{len(scenes)} of the {len(CASES)} conformance cases (every built-in process and graph) "
                f"on {', '.join(backends)}")
    return warm


def _code_path(scene) -> tuple:
    """What decides which kernels a scene calls: its processes' types, connections and choices (the
    parameters that are words or flags, and numbers declared ``selects_code``; other numbers only change
    values), and what its recording carries."""
    network = scene.network

    def choices(process) -> tuple:
        picks = {p.name for p in process.all_params() if p.selects_code}
        return tuple(sorted((k, repr(v)) for k, v in process.values.items()
                            if isinstance(v, (str, bool)) or v is None or k in picks))

    processes = tuple(sorted((type(p).__name__, choices(p)) for p in network.processes))
    edges = tuple(sorted((type(a.process).__name__, a.name, type(b.process).__name__, b.name)
                         for a, b in network.connections()))
    recording = scene.recording
    return processes, edges, recording.trajectory is not None, recording.imu is not None


def _pipeline() -> str:
    import tempfile
    from pathlib import Path

    from tofnet.api import ESTIMATORS, run
    from tofnet.eval.metrics import evaluate
    from tofnet.io import read_recording
    from tofnet.io.source import open_recording
    from tofnet.sim import built_in_scenarios
    from tofnet.sim.run import simulate

    names = list(built_in_scenarios())
    with tempfile.TemporaryDirectory(prefix="tofnet-warmup-") as tmp:
        for name in names:
            folder = Path(tmp) / name
            if not simulate(name, folder, duration=PIPELINE_S, sensor_size=(24, 18))["events"]:
                continue  # a far scene sees no edge this soon; the others call the same kernels
            with open_recording(folder) as source:  # streamed, as `tofnet run` reads a file that names its size
                for _ in source.chunks():
                    pass
            recording = read_recording(folder)
            for estimator in ESTIMATORS:
                result, _ = run(recording, estimator=estimator)
                evaluate(recording, result.depth, {"t0_us": result.t0_us, "timestep_us": result.timestep_us,
                                                   "latency_steps": result.latency_steps})
    import numpy as np
    from tofnet.io.evt3 import decode_words, new_state
    # tofnet's own EVT3 decoder (the files faery's decoder reads need no compiling)
    decode_words(np.array([0x8001, 0x0002, 0x6003, 0x2804, 0x3005, 0x4003], "<u2"), 24, 18, 0, new_state())
    from tofnet.io.event_stream_tail import walk_bytes
    walk_bytes(np.zeros(5, np.uint8), 0, 0xFE)  # the check that an Event Stream file ends on a whole event
    return (f"{len(names)} simulator scenarios ({PIPELINE_S * 1e3:g} ms at 24x18 px) written, read, run with "
            f"{len(ESTIMATORS)} built-in estimators and scored; an EVT3 stream decoded, an Event Stream's end checked")


#: Seconds of each scenario the pipeline warmer simulates (enough for events in every one).
PIPELINE_S = 0.02

def _workers() -> str:
    from tofnet.backends.registry import get_backend
    from tofnet.conformance import get_case

    scene = get_case("patch-d2").build()
    for fuse in (True, False):
        get_backend("fixed", workers=2, fuse=fuse).run(scene.network, scene.recording, record_tot=True)
    scene = get_case("time-surface-texture").build()  # the time surface's bands read clocked columns
    get_backend("fixed", workers=2).run(scene.network, scene.recording)
    touch_as_bands_do()
    return ("the bands' kernels (fixed with 2 workers: the paper's network fused and model by model, the "
            "time surface; the first touch of a large packet's output)")


def touch_as_bands_do() -> None:
    """``kernels.bands.touch`` called with the types ``BandedKernel.run_events`` gives it (``_fresh``: the
    output's bytes, a C-contiguous uint8 view, and Python ints), touching nothing: the real path calls it
    only for packets of ``SERIAL_BELOW`` events or more, in threads, which tiny inputs never are."""
    import numpy as np

    from tofnet.backends.bands import HUGE_PAGE
    from tofnet.events import DEPTH_DTYPE
    from tofnet.kernels.bands import touch

    into = np.empty(1, DEPTH_DTYPE)
    touch(into.view(np.uint8), into.ctypes.data, 0, 0, 0, 2, HUGE_PAGE)


def _multiproc() -> str:
    return _families_warmer(("multiproc",))() + " (its workers compile in their own processes, not counted here)"


register_warmer("backends", _families_warmer(("reference", "float", "fixed")))
register_warmer("pipeline", _pipeline)
register_warmer("workers", _workers)
register_warmer("multiproc", _multiproc)
