"""``--allow-import``: the opt-in a spec or plan needs to import a module (tofnet.io.trust)."""

from __future__ import annotations


def add_allow_import(p) -> None:
    """Add ``--allow-import MODULE`` (repeatable) to a command that loads specs or plans."""
    p.add_argument("--allow-import", action="append", default=[], metavar="MODULE",
                   help="let a spec import MODULE (and its submodules) for a 'MODULE:Class' process type; "
                        "importing runs the module's code; repeatable; also the TOFNET_ALLOW_IMPORT list")
