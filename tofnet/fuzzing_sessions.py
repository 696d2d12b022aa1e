"""Fuzz target for live sessions (issue 27): a recipe of operations, some of them misuses.

Each line of a case is one operation on a live ``Session`` on the fixed backend, with
whole numbers picking its arguments from tables of ordinary and hostile values:
``feed A B U`` (events ``A..B`` of a fixed stream, a promise ``UNTILS[U]``), ``set V X``
(``VARIABLES[V]`` to ``VALUES[X]``), ``monitor X Y`` (a pixel, inside or outside the
sensor), ``run N`` (``run`` on a live session: a misuse). Every refusal must be one line
of ``TofnetError``, and must change nothing: the session then finishes with exactly the
records, counts and monitor samples of a session given only the accepted operations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tofnet.errors import TofnetError
from tofnet.fuzzing_checks import MAX_MESSAGE, require

_SENSOR = (12, 10)
VARIABLES = ("input.last_accepted", "time_of_travel.counter", "time_of_travel.polarity", "depth.a_t",
             "input.refractory", "input.timestep")
VALUES = (0, 1, -(2**62), 2**61 - 1, 2**61, -(2**63), 2**63, float("inf"), float("nan"), 1.5, "x", [1, 2, 3], 1e30,
          300, "2ms", -1)
#: Promises relative to the packet's last event (None: no promise); absolute ones are tuples.
UNTILS = (None, 1, 1000, 0, -1000, (2**63,), (-(2**63),), (2**61,), 1.5, "x")


@dataclass
class Replayed:
    """Both sessions' ends: the fuzzed one (with refusals) and the one given only what it accepted."""

    fuzzed: tuple
    clean: tuple
    refusals: list[str] = field(default_factory=list)


def _events() -> np.ndarray:
    from tofnet.testing import moving_pattern
    return moving_pattern(_SENSOR, (300, -150), 60_000, seed=3)


def _session():
    from tofnet import Session
    from tofnet.compiler import compile_network
    from tofnet.io.recording import ConstantVelocity
    from tofnet.networks import depth_network
    from tofnet.testing import TEST_INTRINSICS

    network = compile_network(depth_network(_SENSOR, velocity={"source": "constant", "velocity": [-0.5, 0.2, 0.1]}))
    return Session(network, backend="fixed", intrinsics=TEST_INTRINSICS,
                   velocity_source=ConstantVelocity([-0.5, 0.2, 0.1]), t0_us=0)


def number(word: str) -> int:
    """A recipe's word as a whole number >= 0 (a word that is not one picks by its length)."""
    try:
        return abs(int(word))
    except ValueError:
        return len(word)


def _operations(data: bytes) -> list[tuple[str, list[int]]]:
    out = []
    for line in data.decode("utf-8", "replace").splitlines()[:40]:
        words = line.split()
        if words and words[0] in ("feed", "set", "monitor", "run"):
            out.append((words[0], [number(w) for w in words[1:4]] + [0, 0, 0]))
    return out


def _apply(session, events: np.ndarray, op: str, args: list[int]) -> None:
    a, b, c = args[:3]
    if op == "feed":
        packet = events[a % (len(events) + 1):b % (len(events) + 1)]
        until = UNTILS[c % len(UNTILS)]
        if isinstance(until, int) and not isinstance(until, bool):
            until = (int(packet["t"][-1]) if len(packet) else 0) + until
        elif isinstance(until, tuple):
            until = until[0]
        session.feed(packet, until_us=until)
    elif op == "set":
        session.set(VARIABLES[a % len(VARIABLES)], VALUES[b % len(VALUES)])
    elif op == "monitor":
        session.add_monitors([f"time_of_travel.counter@{a % 16},{b % 16}"])
    else:
        session.run(steps=a % 5)


def _end(session) -> tuple:
    result = session.finish()
    monitors = [(m.target, m.steps, m.values.tobytes()) for m in session.monitors]
    return result.counts, {k: v.tobytes() for k, v in result.outputs.items()}, monitors


def run_session(data: bytes, folder: Path) -> Replayed:
    """Apply the recipe's operations; replay the accepted ones on a fresh session."""
    events, ops = _events(), _operations(data)
    refusals, accepted = [], []
    with _session() as session:
        for op, args in ops:
            try:
                _apply(session, events, op, args)
                accepted.append((op, args))
            except TofnetError as err:
                refusals.append(str(err))
        try:  # must finish: a refusal never ends a session
            fuzzed = _end(session) if session.stream.executor is not None else None
        except TofnetError as err:
            fuzzed = ("the session could not finish", str(err))
    with _session() as clean:
        for op, args in accepted:
            _apply(clean, events, op, args)
        expected = _end(clean) if clean.stream.executor is not None else None
    return Replayed(fuzzed, expected, refusals)


def check_replayed(result: Replayed) -> None:
    for message in result.refusals:
        require("\n" not in message and len(message) <= MAX_MESSAGE, "a refusal is one line")
    require(result.fuzzed == result.clean, "a refused operation changed the session")


def session_seeds() -> list[bytes]:
    return [b"feed 0 40 0\nset 0 0\nfeed 40 90 1\nmonitor 3 4\nfeed 90 200 2\n",
            b"feed 0 30 1\nset 1 0\nset 4 14\nfeed 30 300 0\n"]


__all__ = ["run_session", "check_replayed", "session_seeds", "number", "Replayed"]
