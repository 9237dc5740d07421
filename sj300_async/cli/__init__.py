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
  sent), a bad snapshot file, a command that changes drives given no bus
  (no ``--url``, ``SJ300_URL`` or ``--sim``; nothing was opened).
- 130: interrupted (Ctrl-C), ``monitor`` included (Ctrl-C is its usual way
  to stop; ``--count``, ``--duration`` and SIGTERM end it with 0).

Every expected failure is one line on stderr, ``sj300 COMMAND: error:
message``; never a traceback. An OS error too, including the ``termios.error``
a serial port answers line settings it cannot do with (not an ``OSError``):
then the line ends with the troubleshooting guide's hint. On the implicit
simulator (no ``--url``, ``--sim`` or ``SJ300_URL``) a ``note:`` line comes
first, once the bus is open (see :mod:`._common`).

The bus options and ``--json`` are global: before or after the subcommand
(see :mod:`._common`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import Final, NoReturn

from .. import __version__
from ..transports import SerialSettingsError
from ..wire import LocalProtocolError, SJ300Error
from ._common import GlobalOptionsOnParent, add_global_options, misplaced_option
from ._errors import FAILURE, INTERRUPTED, USAGE, CliError

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
    "._sniff",
    "._gateway",
    "._shell",
)

_EPILOG = """\
The bus: --url URL, else $SJ300_URL, else --sim: an in-memory simulator of
drives 1-8 (sim://?nodes=1-8) that lives as long as the command: nothing
persists between two commands on it. Without any of the three, commands that
change drives (run, stop, freq, write, params restore, reset) refuse (exit 2);
the others run on that simulator and say so: a note on stderr, and
"simulated": true in JSON objects. `sj300 simulate` serves simulated drives
over TCP, whose state does persist. URLs: tcp://HOST:PORT, /dev/ttyUSB0,
serial:///dev/ttyUSB0?baudrate=9600&parity=E, sim://?nodes=1-8.
`sj300 monitor` without a URL is a live demo of eight busy drives;
`sj300 monitor --url mqtt://HOST:PORT` shows every drive of every gateway
publishing on that broker (`sj300 gateway --mqtt`), read-only.
`sj300 sniff URL` listens to a line through a tap without transmitting
(`sj300 simulate --tap tcp://HOST:PORT` makes one); --capture PATH on any
command writes the frames to a pcapng file (docs/CAPTURE.md);
--url replay://PATH.pcapng answers from such a capture.
`sj300 --sim shell` holds one bus open for a session of commands typed as
here (`freq 30 -n 1`, `run forward -n 1`, `status -n 1`; help, exit): on
sim:// the drives keep their state from one command to the next. History
in $SJ300_HISTORY (default ~/.sj300_history), Tab completes commands and
parameter codes, Ctrl-C stops the running command.

Global options (--url, --sim, --protocol, --timeout, --retries, --baud,
--parity, --bytesize, --stopbits, --trace, --json) go before or after
COMMAND: `sj300 --url tcp://bridge:4001 scan` = `sj300 scan --url ...`;
given on both sides, the one after COMMAND wins.
--json prints results as JSON, keys named after the result fields.
--trace prints every frame on stderr: seconds since the start, → tx / ← rx,
the bytes in hex, and their meaning.
Exit status: 0 success; 1 the bus or a drive failed (time-out, NAK, no
connection) or a check failed; 2 bad arguments; 130 interrupted.
"""


def _os_errors() -> tuple[type[Exception], ...]:
    try:
        import termios
    except ImportError:  # not POSIX
        return (OSError,)
    return (OSError, termios.error)  # termios.error is no OSError


_OS_ERRORS: Final[tuple[type[Exception], ...]] = _os_errors()
_Expected: Final[tuple[type[Exception], ...]] = (CliError, SJ300Error, *_OS_ERRORS)
#: Ends the error line of a port that refuses line settings.
SETTINGS_HINT: Final = (
    "a pseudo-terminal or some USB adapters do not support parity or 7 data bits "
    "(see docs/guide/troubleshooting.md)"
)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line: ``prog: error: message``."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


class _SubParser(_Parser, GlobalOptionsOnParent):
    """A subcommand's parser: its copies of the global options leave ``sj300``'s values be."""


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``sj300`` with every subcommand."""
    parser = _Parser(
        prog="sj300",
        description="Hitachi SJ300 inverters on RS-485.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    add_global_options(parser)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_SubParser)
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
    misplaced = misplaced_option(args)
    if misplaced is not None:
        parser.error(misplaced)
    try:
        return int(run(args))
    except KeyboardInterrupt:
        return INTERRUPTED
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
    if isinstance(exc, _OS_ERRORS) and not isinstance(exc, OSError):  # termios.error
        args = exc.args
        text = f"{args[1]} (errno {args[0]})" if len(args) == 2 else " ".join(map(str, args))
        return f"{text}: {SETTINGS_HINT}"
    text = " ".join(str(exc).split())  # one line, whatever the message holds
    if isinstance(exc, SerialSettingsError):
        return f"{text}: {SETTINGS_HINT}"
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
