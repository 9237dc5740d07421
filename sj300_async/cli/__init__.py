"""The ``sj300`` command line: one subcommand per module.

Each subcommand lives in its own module exposing ``add_parser(subparsers)``,
which adds its parser and sets ``run`` (a function of the parsed arguments
returning the exit status) as a default. Add a module name to
:data:`_SUBCOMMANDS` to add a subcommand.

Exit status: 0 success, 2 usage or startup error (printed as one line on
stderr, never a traceback), 130 after an unexpected interrupt.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import NoReturn

from .. import __version__
from ._errors import CliError

__all__ = ["CliError", "main"]

#: Subcommand modules, in the order ``--help`` lists them.
_SUBCOMMANDS = ("._simulate",)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line: ``prog: error: message``."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``sj300`` with every subcommand."""
    parser = _Parser(prog="sj300", description="Hitachi SJ300 inverters on RS-485.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _SUBCOMMANDS:
        importlib.import_module(name, __name__).add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``sj300`` command line; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    run = getattr(args, "run", None)
    if run is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(run(args))
    except CliError as exc:
        print(f"sj300 {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
