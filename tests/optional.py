"""Optional libraries some tests need, and what installs each: such a test, skipped, says so in one line."""

from __future__ import annotations

from types import ModuleType

import pytest

#: Import name -> what installs it (the extras of pyproject.toml).
INSTALLS = {
    "faery": 'pip install "tofnet[formats]"',
    "h5py": 'pip install "tofnet[hdf5]"',
    "hdf5plugin": 'pip install "tofnet[hdf5plugin]"',
    "rosbags": 'pip install "tofnet[ros]"',
    "distributed": 'pip install "tofnet[batch]"',
    "hypothesis": 'pip install "tofnet[test]"',
    "cv2": 'pip install "tofnet[test]" (opencv-python-headless: the reference undistortion)',
    "plyfile": 'pip install "tofnet[test]" (plyfile: an independent PLY reader)',
    "numpy": "pip install numpy",
}


def optional(module: str) -> ModuleType:
    """``module``, or skip the test (or the whole file, at module level) naming what installs it."""
    return pytest.importorskip(module, reason=f"needs {module}: {INSTALLS[module]}")
