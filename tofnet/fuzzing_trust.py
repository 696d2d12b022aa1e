"""Fuzz targets for specs and plans that name Python modules (issue 27, docs/reliability.md).

A case is a spec (``spec imports``) or a plan (``plan imports``) whose process types are
``module:Class``. It is loaded with a fixed allow list, with the spec's folder on
``sys.path`` (as ``python -m tofnet`` in that folder used to have it) and a library
folder beside it. Whatever the mutations make of the module names, a case must end in a
one-line error or a result such that no module was imported that the allow list does
not name (or that was not already imported), nothing beside the spec ran (its module
leaves a marker file when imported), and a plan stays within ``MAX_TASKS``. The
mutations' tokens include hostile module names (``this``, ``venv.__main__``, the module
beside the spec).
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tofnet.errors import TofnetError

#: An allowed module, in the library folder (``lib/``): defines a process type, writes nothing.
CANARY = "trust_fuzz_canary"
#: A module beside the spec: allowed by name, refused because of where it is; leaves a marker.
BESIDE = "beside_canary"
ALLOW = (CANARY, BESIDE)
MARKER = "BESIDE_RAN"
#: Target name -> the file a case is written to.
TRUST_FILES = {"spec imports": "net.yaml", "plan imports": "plan.yaml"}
_TYPE = re.compile(r"([A-Za-z_][\w.]*)\s*:\s*['\"]?[A-Za-z_]")
# Most words are module names, so that most mutations land on one.
_BODY = ("processes:\n  input: {{type: tofnet.processes.input:InputProcess, sensor_size: [16, 12]}}\n"
         "  gate: {{type: '{0}', parity: 1}}\n  tot: {{type: tofnet.processes.time_of_travel:TimeOfTravelProcess}}\n"
         "connections: [input.events -> gate.events, gate.passed -> tot.events]\n")


@dataclass
class Loaded:
    """What a case did: the network or plan it gave (None after an error) and what it imported."""

    result: Any
    imported: list[str]
    beside_ran: bool


def _setup(folder: Path) -> Path:
    lib = folder / "lib"
    if not (lib / f"{CANARY}.py").exists():
        lib.mkdir(exist_ok=True)
        (lib / f"{CANARY}.py").write_text("from tofnet.testing import ParityGateProcess\n\n\n"
                                          "class CanaryGateProcess(ParityGateProcess):\n    pass\n")
        (folder / f"{BESIDE}.py").write_text(f"import pathlib\npathlib.Path(__file__).with_name({MARKER!r})"
                                             ".write_text('ran')\n")
        from tofnet.events import make_events
        np.save(folder / "a.npy", make_events([0, 1000], [1, 2], [1, 1], [1, 0]))
        for name, type_name in (("good", f"{CANARY}:CanaryGateProcess"), ("testing", "tofnet.testing:ParityGateProcess"),
                                ("zen", "this:X"), ("beside", f"{BESIDE}:X")):
            (folder / f"{name}.yaml").write_text(_BODY.format(type_name))
    (folder / MARKER).unlink(missing_ok=True)
    return lib


def _named_modules(folder: Path) -> set[str]:
    """Every ``module`` a ``module:Class`` in the folder's YAML files could name."""
    return {m.group(1) for path in folder.glob("*.yaml") for m in _TYPE.finditer(path.read_text(errors="replace"))}


def _load(name: str):
    def run(data: bytes, folder: Path) -> Loaded:
        import tofnet.processes  # noqa: F401 - imported: naming them needs no opt-in
        import tofnet.testing  # noqa: F401
        lib = _setup(folder)
        path = folder / TRUST_FILES[name]
        path.write_bytes(data)
        before = set(sys.modules)
        sys.path[:0] = [str(folder), str(lib)]
        result, error = None, None
        try:
            if name == "spec imports":
                from tofnet.io.spec import load_spec
                result = load_spec(path, allow_import=ALLOW).network
            else:
                from tofnet.batch import load_plan
                result = load_plan(path, allow_import=ALLOW)
        except TofnetError as err:
            error = err
        finally:
            for entry in (str(folder), str(lib)):
                sys.path.remove(entry)
        imported = sorted(m for m in _named_modules(folder) if m in sys.modules and m not in before
                          and not any(m == a or m.startswith(a + ".") for a in ALLOW))
        loaded = Loaded(result, imported, (folder / MARKER).exists())
        if error is not None and not imported and not loaded.beside_ran:
            raise error
        return loaded
    return run


def check_trusted(loaded: Loaded) -> None:
    """No module outside the allow list imported, nothing beside the spec run, a plan bounded."""
    from tofnet.batch.bounds import MAX_TASKS
    from tofnet.fuzzing_checks import check_network, require
    require(not loaded.imported, f"only allowed modules are imported (imported {loaded.imported})")
    require(not loaded.beside_ran, "a module beside the spec never runs")
    if loaded.result is None:
        return
    if hasattr(loaded.result, "size"):
        require(loaded.result.size() <= MAX_TASKS, "a plan has at most MAX_TASKS tasks")
    else:
        check_network(loaded.result)


def trust_targets() -> dict[str, tuple]:
    """Target name -> (run, check), for ``tofnet.fuzzing.TARGETS``."""
    return {name: (_load(name), check_trusted) for name in TRUST_FILES}


#: Module and class names a generated case picks from: allowed, imported, hostile, malformed.
MODULES = (CANARY, f"{CANARY}.sub", BESIDE, "tofnet.testing", "tofnet.processes.input", "tofnet", "this",
           "venv.__main__", "tofnet.__main__", "os", "json", "no_such_module", "..x", "a..b", "", "é", "this.that")
CLASSES = ("CanaryGateProcess", "ParityGateProcess", "InputProcess", "X", "__class__", "", "Process")
GLOBS = ("*.npy", "**/*.npy", "../*.npy", "lib/../*.npy", "**/**/*.npy", "[", "lib/**", "a.npy")
SPECS = ("good.yaml", "testing.yaml", "zen.yaml", "beside.yaml", "paper", "../good.yaml")


def trust_case(rng, name: str) -> bytes:
    """A generated case: a spec of random ``module:Class`` types, or a plan of random specs,
    globs and grid sizes (``rng``: a ``random.Random``); mutation alone rarely reaches them."""
    if name == "spec imports":
        return _BODY.replace("tofnet.processes.input:InputProcess", _type(rng)).format(_type(rng)[1:-1]).encode()
    lines = [f"recordings: [{{glob: '{rng.choice(GLOBS)}'}}]",
             f"networks: [{', '.join(f'{{spec: {rng.choice(SPECS)}, name: n{i}}}' for i in range(rng.randint(1, 3)))}]"]
    sizes = [rng.choice((1, 2, 30, 200, 255)) for _ in range(rng.randint(0, 3))]
    keys = ("distance", "update-every", "refractory")[:len(sizes)]
    values = {"distance": lambda n: list(range(1, n + 1)), "update-every": lambda n: list(range(1, n + 1)),
              "refractory": lambda n: [f"{k}us" for k in range(1, n + 1)]}
    if sizes:
        lines.append("grid:")
        lines += [f"  {k}: {values[k](n)}" for k, n in zip(keys, sizes)]
    return ("\n".join(lines) + "\n").encode()


def _type(rng) -> str:
    return f"'{rng.choice(MODULES)}:{rng.choice(CLASSES)}'"


def trust_seeds(name: str) -> list[bytes]:
    """Valid cases: a spec naming the allowed module (and an imported one), plans using them."""
    if name == "spec imports":
        return [_BODY.format(f"{CANARY}:CanaryGateProcess").encode(),
                _BODY.format("tofnet.testing:ParityGateProcess").encode()]
    return [b"recordings: ['*.npy']\nnetworks: [good.yaml, {spec: testing.yaml, name: t}]\n"
            b"grid: {refractory: [20ms, 40ms], distance: [1, 2]}\n",
            b"recordings: [{glob: '**/*.npy'}]\nnetworks: [paper]\n"]
