"""``--allow-import``: the opt-in a spec or plan needs to import a module (tofnet.io.trust)."""

from __future__ import annotations

import argparse


def add_allow_import(p) -> None:
    """Add ``--allow-import MODULE`` (repeatable) to a command that loads specs or plans."""
    p.add_argument("--allow-import", action="append", default=[], metavar="MODULE", type=module_option,
                   help="let a spec import MODULE (and its submodules) for a 'MODULE:Class' process type; "
                        "importing runs the module's code; repeatable; also the TOFNET_ALLOW_IMPORT list")


def module_option(text: str) -> str:
    """``--allow-import``'s value: module names (one, or a comma/space list) that exist on the Python
    path, found without importing them; argparse turns the error into one line naming the option."""
    from tofnet.errors import SpecError
    from tofnet.io.trust import module_findable, module_names
    try:
        names = module_names([text])
    except SpecError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    if not names:
        raise argparse.ArgumentTypeError("expected a module name such as my_package.my_module, got nothing")
    for name in names:
        if not module_findable(name):
            raise argparse.ArgumentTypeError(f"no module {name!r} on the Python path; install it, or name its "
                                             "folder in PYTHONPATH")
    return text
