"""MVSEC, TUM-VIE and M3ED sequence folders (see ``tofnet.io.sequences``)."""

from __future__ import annotations

from pathlib import Path


def other_kind(folder: Path) -> str | None:
    """``mvsec``, ``tumvie`` or ``m3ed`` for a folder of that layout, else ``None``."""
    return None


def open_other(folder: Path, kind: str, side: str, allow_external: bool):
    raise NotImplementedError(kind)
