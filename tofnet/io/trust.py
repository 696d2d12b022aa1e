"""What a spec, plan or compiled network from someone else may make tofnet do.

A spec's process ``type: "package.module:ClassName"`` names Python code; importing a module
runs it. So a module is imported only when the user opted in: ``--allow-import MODULE``
on the command line, the ``TOFNET_ALLOW_IMPORT`` list in the environment, or
``allow_import=`` in Python. Needing no opt-in: a module already imported (importing it
again runs nothing) and the target of an installed ``tofnet.processes`` entry point (the
user installed that package). The check runs before any import, and a module that would
come from the spec's own folder is refused unless that folder is named in ``PYTHONPATH``.
The threat model is in docs/reliability.md ("Files from strangers").
"""

from __future__ import annotations

import logging
import os
import re
import sys
from importlib.machinery import PathFinder
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Iterable, Mapping

from tofnet.errors import SpecError, quote
from tofnet.machine import cpu_count

#: Environment variable: modules a spec may import, separated by commas or spaces.
ENV_ALLOW_IMPORT = "TOFNET_ALLOW_IMPORT"
#: Entry-point group through which installed packages offer process types to specs.
ENTRY_POINTS = "tofnet.processes"
_MODULE = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")
_HOW = "--allow-import {m} (or {env}={m}; allow_import=[{m!r}] in Python)"


def allowed_imports(allow_import: Iterable[str] | str | None = None) -> tuple[str, ...]:
    """The modules a spec may import: ``allow_import`` (names, or one comma/space list) and
    ``TOFNET_ALLOW_IMPORT``. A name allows the module and its submodules (``pkg`` allows
    ``pkg.mod``)."""
    given = [allow_import] if isinstance(allow_import, str) else list(allow_import or ())
    return tuple(dict.fromkeys(module_names([*given, os.environ.get(ENV_ALLOW_IMPORT, "")])))


def module_names(texts: Iterable[str]) -> list[str]:
    """The module names in ``texts`` (each one name or a comma/space list); ``SpecError`` for one
    that is not a dotted name."""
    names = [n for text in texts for n in re.split(r"[,\s]+", text) if n]
    for name in names:
        if not _MODULE.match(name):
            raise SpecError(f"allowed import {quote(name)}: expected a module name such as my_package.my_module")
    return names


def check_import(type_name: str, allow: tuple[str, ...], spec_dir: Path | None = None) -> str:
    """Refuse, before importing anything, a ``module:Class`` type the user did not allow.

    Returns the module name. Raises ``SpecError`` (one line saying how to allow it) when the
    module is neither already imported, an entry point's, nor allowed, or when it would be
    found in ``spec_dir`` (the spec's folder) without that folder being in ``PYTHONPATH``.
    """
    module_name, _, attr = type_name.partition(":")
    if not _MODULE.match(module_name) or not attr.isidentifier():
        raise SpecError(f"{quote(type_name)} is not 'package.module:ClassName'")
    if module_name in sys.modules or _is_entry_point(module_name):
        return module_name
    if not any(module_name == a or module_name.startswith(a + ".") for a in allow):
        raise SpecError(f"process type {quote(type_name)} imports module {quote(module_name)}, which runs its code; "
                        f"if you trust it, allow it with {_HOW.format(m=module_name, env=ENV_ALLOW_IMPORT)}")
    if spec_dir is not None:
        _refuse_spec_folder(module_name, spec_dir)
    return module_name


def module_findable(module_name: str) -> bool:
    """Whether ``module_name`` is imported, built in or importable, found by asking the import
    system's finders where it is (nothing is imported, no code of the module runs)."""
    if module_name in sys.modules or module_name in sys.builtin_module_names or _is_entry_point(module_name):
        return True
    parts = module_name.split(".")
    path = None
    for i in range(len(parts)):
        name = ".".join(parts[:i + 1])
        if name in sys.modules:
            path = getattr(sys.modules[name], "__path__", None)
            continue
        found = _find_spec(name, path)
        if found is None:
            return False
        path = found.submodule_search_locations
    return True


def _find_spec(name: str, path) -> Any:
    """Where the finders of ``sys.meta_path`` would load ``name`` from (``path``: its package's
    folders), or None: the file system's finder and those that editable installs add (setuptools,
    editables: a name mapped to a project folder) only look."""
    for finder in sys.meta_path:
        find = getattr(finder, "find_spec", None)
        found = find(name, path) if find is not None else None
        if found is not None:
            return found
    return None


def _is_entry_point(module_name: str) -> bool:
    return any(getattr(ep, "value", "").partition(":")[0].strip() == module_name
               for ep in entry_points(group=ENTRY_POINTS))


def _refuse_spec_folder(module_name: str, spec_dir: Path) -> None:
    top = module_name.split(".")[0]
    if top in sys.modules:
        return
    found = PathFinder.find_spec(top)  # looks at the file system only; runs nothing
    if found is None:
        return
    where = [Path(p) for p in found.submodule_search_locations or ()] or [Path(found.origin or ".")]
    folder = spec_dir.resolve()
    if not any(p.resolve().parent == folder for p in where):
        return
    named = {Path(p).resolve() for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p}
    if folder not in named:
        raise SpecError(f"module {quote(module_name)} would be imported from the spec's own folder {folder}; "
                        "name that folder in PYTHONPATH if you trust its code")


# ---------------------------------------------------------------- files a spec names

def file_a_spec_names(named: str, folder: Path, setting: str = "PROCESS.PARAM") -> str:
    """The file a spec read from ``folder`` names (a parameter declared ``reads_file``), as the run opens it.

    A relative name is taken from the spec's folder, so a spec and its files read the same from
    any working folder. Raises ``SpecError`` when the file lies outside that folder once links and
    ``..`` are resolved, as a container build's context keeps to its folder: a spec from someone
    else cannot make tofnet read, and quote in an error, ``/proc/self/environ``, ``~/.netrc`` or what
    a link they sent along points at. The user names a file elsewhere (``--set PROCESS.PARAM=FILE``,
    ``Process.set_param``); ``setting`` names the parameter so.
    """
    from tofnet.io.files import lies_in
    path = Path(named)
    opened = path if path.is_absolute() else folder / path
    if not lies_in(opened, folder):
        raise SpecError(f"{quote(named)} lies outside the spec's folder {folder}, links resolved; a spec reads only "
                        f"files in its own folder or below it; name a file elsewhere on the command line (tofnet "
                        f"run or live --set {setting}=FILE) or in Python (set_param)")
    return str(opened)


# ---------------------------------------------------------------- resources

def cap_workers(options: Mapping[str, Any], where: str) -> dict[str, Any]:
    """``options`` with every worker count (``workers``, ``*_workers``) above the CPU count
    lowered to it, saying so in one warning line of tofnet's log (the CLI prints it as
    ``tofnet COMMAND: warning: ...``) naming ``where``; other values are left to the backend."""
    out = dict(options)
    cpus = cpu_count()
    for key, value in options.items():
        if (key == "workers" or key.endswith("_workers")) and isinstance(value, int) \
                and not isinstance(value, bool) and value > cpus:
            logging.getLogger(__name__).warning(f"warning: {where}.{key}: {value} workers capped to this "
                                                f"machine's {cpus} CPUs")
            out[key] = cpus
    return out
