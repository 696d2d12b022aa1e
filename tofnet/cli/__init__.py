"""The ``tofnet`` command. Each subcommand is a module here with ``register(subparsers)``."""

from __future__ import annotations

import argparse
import importlib
import re
import sys

from tofnet.errors import TofnetError, interrupted

#: Subcommand modules, in the order ``tofnet --help`` lists them.
SUBCOMMANDS = ("demo", "run", "simulate", "eval", "plot", "compile", "conformance", "info", "convert", "export",
               "batch", "warmup", "live")
#: A value that argparse would take for an option: a minus, then a digit or a point (``-0.5,0,0``, ``-1s``).
_NEGATIVE_VALUE = re.compile(r"-\.?\d")


class _Parser(argparse.ArgumentParser):
    """argparse's parser with its errors on one line (no usage block), as the commands' own errors."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")

    def parse_args(self, args=None, namespace=None):
        """As argparse's, but unknown options are said by the subcommand's parser (``tofnet run: error: ...
        (see 'tofnet run --help')``), with the closest option of that subcommand when one is close."""
        commands = {name: sub for action in self._actions if isinstance(action, argparse._SubParsersAction)
                    for name, sub in action.choices.items()}
        args = list(sys.argv[1:] if args is None else args)
        parsed, extras = self.parse_known_args(_negative_values_joined(args, commands.get(args[0] if args else None,
                                                                                         self)), namespace)
        if extras:
            parser = commands.get(getattr(parsed, "command", None), self)
            parser.error(f"unrecognized arguments: {' '.join(extras)}{parser.did_you_mean(extras)}")
        return parsed

    def did_you_mean(self, extras: list[str]) -> str:
        """``; did you mean --duration?`` for the first unknown option close to one of this parser's."""
        import difflib

        options = [option for action in self._actions for option in action.option_strings if option.startswith("--")]
        for word in extras:
            if word.startswith("--"):
                close = difflib.get_close_matches(word.partition("=")[0], options, n=1)
                if close:
                    return f"; did you mean {close[0]}?"
        return ""


def _negative_values_joined(args: list[str], parser: argparse.ArgumentParser) -> list[str]:
    """``--velocity -0.5,0,0`` as ``--velocity=-0.5,0,0``: argparse takes a value that starts with a minus, unless
    it is a plain number, for an option, and says the option expected one argument."""
    takes_value = {option for action in parser._actions if action.nargs != 0 for option in action.option_strings}
    joined: list[str] = []
    for token in args:
        if joined and joined[-1] in takes_value and _NEGATIVE_VALUE.match(token):
            joined[-1] = f"{joined[-1]}={token}"
        else:
            joined.append(token)
    return joined


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="tofnet",
        description="Low-latency depth from event timing: simulate, compile, run and evaluate the paper's network.")
    from tofnet import __version__
    parser.add_argument("--version", action="version", version=f"tofnet {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"tofnet.cli.{name}")
        except ModuleNotFoundError as err:
            if err.name != f"tofnet.cli.{name}":
                raise
            continue  # not built yet in this checkout
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; user errors print one line and exit 2, never a traceback."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help()
        return 2
    from tofnet.cli.progress import log_to_stderr
    from tofnet.io.guard import reading

    try:  # reading(): the files the command reads, which no output may replace
        with log_to_stderr(args.command), reading():
            return int(args.handler(args) or 0)
    except TofnetError as err:
        print(f"tofnet {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"tofnet {args.command}: interrupted", file=sys.stderr)
        return 130
    except SystemError as err:  # Ctrl-C inside a compiled kernel: numba's dispatcher wraps it in a SystemError
        if not interrupted(err):
            raise
        print(f"tofnet {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `tofnet eval ... | head`): stop quietly.
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
