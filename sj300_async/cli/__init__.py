"""The ``sj300`` command line: one subcommand per module.

Each subcommand lives in its own module exposing ``add_parser(subparsers)``,
which adds its parser and sets ``run`` (a function of the parsed arguments
returning the exit status) as a default. Add a module name to
:data:`_SUBCOMMANDS` to add a subcommand.

Exit status:

- 0: success.
- 1: the bus or a drive failed (time-out, NAK, unreachable bridge, a file
  that cannot be read or written), or a check did not pass (``params
  restore`` verification, ``params diff`` differences, ``scan`` finding
  nobody). ``params diff`` follows diff(1): 1 means different, 2 trouble.
- 2: bad arguments or a request the protocol does not allow (nothing was
  sent), a bad snapshot file.
- 130: interrupted (Ctrl-C), ``monitor`` included (Ctrl-C is its usual way
  to stop; ``--count``, ``--duration`` and SIGTERM end it with 0).

Every expected failure is one line on stderr, ``sj300 COMMAND: error:
message``; never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import NoReturn

from .. import __version__
from ..wire._errors import LocalProtocolError, SJ300Error
from ._errors import FAILURE, USAGE, CliError

__all__ = ["CliError", "main"]

#: Subcommand modules, in the order ``--help`` lists them.
_SUBCOMMANDS = (
    "._monitor",
    "._scan",
    "._status",
    "._read",
    "._write",
    "._run",
    "._stop",
    "._reset",
    "._freq",
    "._trips",
    "._params",
    "._simulate",
    "._shell",
)

_EPILOG = """\
The bus: --url URL, else $SJ300_URL, else an in-memory simulator of drives 1-8
(sim://?nodes=1-8) that lives as long as the command: nothing persists between
two commands on it. `sj300 simulate` serves simulated drives over TCP, whose
state does persist. URLs: tcp://HOST:PORT, /dev/ttyUSB0,
serial:///dev/ttyUSB0?baudrate=9600&parity=E, sim://?nodes=1-8.
`sj300 monitor` without a URL is a live demo of eight busy drives.

--json prints results as JSON, keys named after the result fields.
Exit status: 0 success; 1 the bus or a drive failed (time-out, NAK, no
connection) or a check failed; 2 bad arguments; 130 interrupted.
"""

_Expected = (CliError, SJ300Error, OSError)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line: ``prog: error: message``."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``sj300`` with every subcommand."""
    parser = _Parser(
        prog="sj300",
        description="Hitachi SJ300 inverters on RS-485.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
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
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # The reader went away (``sj300 monitor | head``): not worth a message.
        # Point stdout at /dev/null so the interpreter's final flush stays quiet.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return FAILURE
    except _Expected as exc:
        return _fail(args, exc)
    except BaseExceptionGroup as group:  # from a task group: report its first expected error
        leaf = _first_expected(group)
        if leaf is None:
            raise
        return _fail(args, leaf)


def _fail(args: argparse.Namespace, exc: BaseException) -> int:
    command = getattr(args, "command_name", None) or args.command
    print(f"sj300 {command}: error: {_message(exc)}", file=sys.stderr, flush=True)
    if isinstance(exc, CliError):
        status = exc.status
    elif isinstance(exc, LocalProtocolError):
        status = USAGE
    else:
        status = FAILURE
    if status == FAILURE:  # a subcommand may report trouble otherwise (diff: 2)
        status = getattr(args, "failure_status", FAILURE)
    return status


def _message(exc: BaseException) -> str:
    if isinstance(exc, OSError) and not isinstance(exc, SJ300Error) and exc.strerror:
        return f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    text = " ".join(str(exc).split())  # one line, whatever the message holds
    return text or type(exc).__name__


def _first_expected(group: BaseExceptionGroup[BaseException]) -> BaseException | None:
    for exc in group.exceptions:
        if isinstance(exc, BaseExceptionGroup):
            found = _first_expected(exc)
            if found is not None:
                return found
        elif isinstance(exc, _Expected):
            return exc
    return None
