"""A cached kernel recompiles when a file it depends on changes, not only its own (numba keys on its own)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

RUN = """
import sys
sys.path.insert(0, {pkg_parent!r})
{register}
from cached_pkg.caller import twice
print(twice(1))
"""


def _write_package(parent: Path, value: int) -> None:
    pkg = parent / "cached_pkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "callee.py").write_text(f"import numba\n\n@numba.njit(cache=True)\ndef value(x):\n    return x * {value}\n")
    (pkg / "caller.py").write_text("import numba\nfrom cached_pkg.callee import value\n\n"
                                   "@numba.njit(cache=True)\ndef twice(x):\n    return 2 * value(x)\n")


def _run(parent: Path, cache: Path, register: bool) -> int:
    code = RUN.format(pkg_parent=str(parent), register=(
        f"from tofnet.numba_cache import register_root; register_root({str(parent / 'cached_pkg')!r})"
        if register else ""))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return int(done.stdout.strip())


@pytest.mark.parametrize("register", [False, True])
def test_a_change_to_a_called_kernels_file_recompiles_the_caller(tmp_path, register):
    _write_package(tmp_path, 3)
    assert _run(tmp_path, tmp_path / "cache", register) == 6  # compiled and cached
    callee = tmp_path / "cached_pkg" / "callee.py"
    _write_package(tmp_path, 5)  # only the called kernel's file changes
    stat = callee.stat()
    os.utime(callee, ns=(stat.st_atime_ns, stat.st_mtime_ns + 2_000_000_000))
    got = _run(tmp_path, tmp_path / "cache", register)
    # numba alone keeps the caller's stale machine code (6); keyed on the whole package, it recompiles (10)
    assert got == (10 if register else 6)


def test_tofnets_kernels_are_keyed_on_all_of_its_sources():
    import numba.core.caching as caching

    import tofnet.kernels  # noqa: F401 - registers before its kernels are defined
    from tofnet.kernels.time_surface import process
    from tofnet.numba_cache import _WholeSourceStamp

    locator = process._cache._impl.locator
    assert isinstance(locator, _WholeSourceStamp)
    assert isinstance(locator.get_source_stamp()[1], str)
    assert caching.CacheImpl._locator_classes[0].__mro__[1] is _WholeSourceStamp


LOCATE = """
import sys
sys.path.insert(0, {pkg_parent!r})
from tofnet.numba_cache import register_root
register_root({root!r})
from cached_pkg.caller import twice
print(twice(1))
"""


@pytest.mark.parametrize("checkout", [False, True])
def test_an_installed_package_caches_in_the_users_folder_not_beside_its_sources(tmp_path, checkout):
    # pip uninstall leaves files it did not install: kernels cached in site-packages/PKG would keep a folder
    # there that Python imports as an empty namespace package, shadowing a later install of the package
    parent = tmp_path / "site-packages"
    parent.mkdir()
    _write_package(parent, 3)
    if checkout:
        (parent / "pyproject.toml").write_text("[project]\nname = 'cached_pkg'\n")
    user_cache = tmp_path / "xdg-cache"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=str(ROOT), XDG_CACHE_HOME=str(user_cache))
    code = LOCATE.format(pkg_parent=str(parent), root=str(parent / "cached_pkg"))
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "6"
    beside = list((parent / "cached_pkg").rglob("*.nb[ic]"))
    in_user_folder = list(user_cache.rglob("*.nb[ic]"))
    if checkout:
        assert beside and not in_user_folder
    else:
        assert in_user_folder and not beside
