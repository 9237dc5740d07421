"""What every bus subcommand shares: where the bus is, how to talk to it, which drive.

Which bus. ``--url`` picks the transport (see :func:`sj300_async.parse_bus_url`);
without it, the ``SJ300_URL`` environment variable; ``--sim`` says "the
in-memory simulator" explicitly (:data:`DEFAULT_URL`, eight drives; for
``monitor`` its demo). That simulator lives only as long as the command:
nothing done by one invocation (a run command, a parameter write) is seen by
the next. Point several commands at one ``sj300 simulate`` over ``tcp://``
to keep state between them.

Without any of the three, the bus is *implicit*, and what happens is a
property of the subcommand, declared in one place, :data:`CHANGES_DRIVES`:

- a command that changes a drive (``run``, ``stop``, ``freq``, ``write``,
  ``params restore``, ``reset``) is refused before anything is opened or
  sent: exit 2, one line naming the three ways to say which bus;
- every other command (``status``, ``read``, ``trips``, ``scan``, ``params
  backup``/``diff``, ``monitor``...) runs on the simulator and says so:
  once the bus is open, a note on stderr (``sj300 status: note: no --url
  given: these are simulated drives (sim://?nodes=1-8)``), and with
  ``--json`` a ``"simulated": true`` field in every JSON *object* printed
  (:func:`~._output.print_json` adds it last; ``monitor`` prints one object
  per sample, each marked). A JSON document that is not an object (a list)
  is left as it is, never wrapped, so its shape does not depend on the bus:
  the note on stderr is then the only mark. No command prints one today.
  With ``--sim``, ``SJ300_URL`` or ``--url sim://...`` the simulator was
  asked for: no note, no field. In ``sj300 shell`` the session's bus was
  chosen when the shell started (which followed these rules as a read-only
  command): the commands it runs are neither refused nor marked.

Global options. The options of :func:`add_bus_options` (``--url``,
``--sim``, ``--timeout``, ``--retries``, ``--protocol``, ``--trace``, the line
settings) and ``--json`` may come before the subcommand or after it:
``sj300 --url tcp://bridge:4001 scan`` is ``sj300 scan --url
tcp://bridge:4001``. The main parser holds them with their defaults
(:func:`add_global_options`); each subcommand's parser holds copies whose
default is ``argparse.SUPPRESS``, so a value given before the subcommand is
not overwritten by the subcommand's default. Given on both sides, the later
one (after the subcommand) wins. ``--retries`` defaults per subcommand
(``scan`` 0): the main parser's None means "the subcommand's". An option
given before a subcommand that does not take it (``sj300 --url X
simulate``) is refused rather than ignored. The subcommand parsers are told
apart by class (:class:`GlobalOptionsOnParent`); a parser of another class
given :func:`add_bus_options` (a test's, a tool's) gets plain defaults.

``--baud``, ``--parity``, ``--bytesize`` and ``--stopbits`` are the line
settings, the same as the URL's ``baudrate=...`` query (and they win over
it). On a serial port they configure the UART; over ``tcp://`` they
describe the RS-485 line behind the bridge, which sets the computed reply
time-outs; on ``sim://`` they are the simulated line's speed, paced with
``pace=1``. Settings not given keep the URL's, else 19200 8N1.

Protocols. ``--protocol NAME`` (or ``protocol=NAME`` in the URL; the
choices are the registered protocols that have a profile) picks the
drives' protocol, SJ300 by default. Every command works through the
protocol's profile (:mod:`sj300_async.profiles`): node numbers are checked
against its range and named with its noun (FR-700 stations 0..31), and a
command that needs what a protocol's drives lack (a trip history, a
broadcast, a parameter backup format) says so before anything is opened
(:func:`open_cli_bus`'s ``needs``).

``--trace`` prints every frame on stderr as it crosses the line (see
:mod:`._trace`), for every command: :func:`open_cli_bus` sets the hook.
``--capture PATH`` writes them to a pcapng file (docs/CAPTURE.md); in
``sj300 shell`` the file covers the whole session.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import os
import sys
from collections.abc import AsyncIterator, Iterator, Sequence
from contextlib import asynccontextmanager, contextmanager
from typing import Any, Final

from ..bus import DEFAULT_PROTOCOL, Bus, open_bus, parse_bus_url
from ..profiles import Profile, get_profile, profiled_protocols
from ..wire import LineSettings
from ._errors import CliError
from ._output import simulated_output
from ._session import lent_bus

__all__ = [
    "CHANGES_DRIVES",
    "DEFAULT_URL",
    "ENV_URL",
    "GlobalOptionsOnParent",
    "add_bus_options",
    "add_global_options",
    "add_json_option",
    "add_node_option",
    "bus_url",
    "cli_profile",
    "command_name",
    "misplaced_option",
    "node_number",
    "open_cli_bus",
    "positive_float",
    "profile_of",
    "require",
]

#: The environment variable that gives the bus URL when ``--url`` does not.
ENV_URL: Final = "SJ300_URL"
#: The bus when neither ``--url`` nor ``SJ300_URL`` is given: a fresh in-memory simulator.
DEFAULT_URL: Final = "sim://?nodes=1-8"
#: The subcommands that change a drive: refused without ``--url``, ``SJ300_URL`` or ``--sim``
#: (names as :func:`command_name` gives them). A new one opts in here.
CHANGES_DRIVES: Final = frozenset({"run", "stop", "freq", "write", "params restore", "reset"})
#: Where the main parser notes the global options given before the subcommand.
_GIVEN_BEFORE: Final = "global_options_given_before"


def positive_float(text: str) -> float:
    """argparse type: a finite number of seconds > 0 (an infinite time-out is a hang)."""
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _retries(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return value


def node_number(text: str) -> int:
    """argparse type: a drive's address, a whole number (the protocol's range is checked later)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a node is a whole number, got {text!r}") from None
    return value


class GlobalOptionsOnParent:
    """Marks a subcommand's parser whose parent (``sj300``) holds the global options.

    Its copies of them default to ``argparse.SUPPRESS``: a value given before
    the subcommand stays unless the option is given again after it.
    """


class _GivenBefore(argparse.Action):
    """The main parser's global option: stored, and noted as given before the subcommand."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        setattr(namespace, self.dest, self.const if self.nargs == 0 else values)
        given = [*getattr(namespace, _GIVEN_BEFORE, ()), (option_string, self.dest)]
        setattr(namespace, _GIVEN_BEFORE, given)


class _Adder:
    """Adds one set of the shared options: the main parser's, or a subcommand's copies."""

    def __init__(self, parser: argparse.ArgumentParser, *, main: bool) -> None:
        self.main = main
        self.suppress = isinstance(parser, GlobalOptionsOnParent)

    def value(self, group: Any, *flags: str, default: Any = None, **kwargs: Any) -> None:
        if self.main:
            kwargs["action"] = _GivenBefore
        group.add_argument(
            *flags, default=argparse.SUPPRESS if self.suppress else default, **kwargs
        )

    def flag(self, group: Any, *flags: str, **kwargs: Any) -> None:
        if self.main:
            group.add_argument(
                *flags, action=_GivenBefore, nargs=0, const=True, default=False, **kwargs
            )
        else:
            default = argparse.SUPPRESS if self.suppress else False
            group.add_argument(*flags, action="store_true", default=default, **kwargs)


def _add_shared_options(
    parser: argparse.ArgumentParser, add: _Adder, *, default_url: str | None, retries: int | None
) -> None:
    name = parser.prog.partition(" ")[2]  # "sj300 params restore" -> "params restore"
    if add.main:
        where = (
            f"default ${ENV_URL}; without either (or --sim), commands that change drives "
            "refuse, the others use a throw-away simulator and say so"
        )
        retries_default = "the command's: 2, scan 0"
    elif name in CHANGES_DRIVES:
        where = f"default ${ENV_URL}; without either (or --sim) {name} refuses: it changes drives"
        retries_default = str(retries)
    else:
        fallback = "the built-in demo" if default_url is None else f"a throw-away {default_url}"
        where = f"default ${ENV_URL}, else {fallback}, noted on stderr"
        retries_default = str(retries)
    if add.main:
        bus = parser.add_argument_group(
            "global options",
            "before or after COMMAND; given on both sides, the one after COMMAND wins",
        )
    else:
        bus = parser.add_argument_group(
            "bus",
            f"also before the command (sj300 --url URL {name or 'COMMAND'}); "
            "given on both sides, the one after it wins",
        )
    add.value(
        bus,
        "--url",
        metavar="URL",
        help=f"tcp://HOST:PORT, /dev/ttyUSB0, serial://PATH?baudrate=..., sim://?nodes=1-8 "
        f"({where})",
    )
    add.flag(
        bus,
        "--sim",
        help=f"use the in-memory simulator ({DEFAULT_URL}; monitor: its demo), which keeps no "
        "state between commands",
    )
    add.value(
        bus,
        "--timeout",
        type=positive_float,
        metavar="SECONDS",
        help="reply time-out (default: computed from the line speed)",
    )
    add.value(
        bus,
        "--retries",
        type=_retries,
        default=retries,
        metavar="N",
        help=f"attempts after the first on a time-out or a damaged reply (default "
        f"{retries_default})",
    )
    add.value(
        bus,
        "--protocol",
        choices=profiled_protocols(),
        help=f"the drives' protocol (default: the URL's protocol=, else {DEFAULT_PROTOCOL})",
    )
    add.flag(
        bus,
        "--trace",
        help="print every frame on stderr: seconds since the start, → tx / ← rx, hex, meaning",
    )
    add.value(
        bus,
        "--capture",
        metavar="PATH",
        help="write every frame that crosses the line to PATH, a pcapng file "
        "Wireshark opens (docs/CAPTURE.md)",
    )
    about_line = (
        "a serial port's UART; for tcp:// the line behind the bridge (time-outs); "
        "the URL's query otherwise, else 19200 8N1"
    )
    if add.main:  # sj300's help is preformatted (its epilog): wrapped here
        about_line = about_line.replace("(time-outs); ", "(time-outs);\n")
    line = parser.add_argument_group("line settings", about_line)
    add.value(line, "--baud", type=int, metavar="BPS", help="line speed")
    add.value(line, "--parity", type=str.upper, choices=("N", "E", "O"))
    add.value(line, "--bytesize", type=int, choices=(7, 8))
    add.value(line, "--stopbits", type=int, choices=(1, 2))


def add_global_options(parser: argparse.ArgumentParser) -> None:
    """Add the bus options and ``--json`` to the main parser, as global options.

    Each notes that it was given before the subcommand, for
    :func:`misplaced_option`.
    """
    add = _Adder(parser, main=True)
    _add_shared_options(parser, add, default_url=DEFAULT_URL, retries=None)
    output = parser.add_argument_group("output")
    add.flag(output, "--json", help="print JSON (keys are the result field names)")


def add_bus_options(
    parser: argparse.ArgumentParser,
    *,
    default_url: str | None = DEFAULT_URL,
    retries: int = 2,
) -> None:
    """Add ``--url``, ``--sim``, ``--timeout``, ``--retries``, ``--trace`` and the line settings.

    Args:
        default_url: the bus ``--sim`` or nothing names (None: the command's
            own, e.g. monitor's demo).
        retries: ``--retries``'s default for this command.
    """
    _add_shared_options(
        parser, _Adder(parser, main=False), default_url=default_url, retries=retries
    )
    parser.set_defaults(default_url=default_url, default_retries=retries, takes_bus_options=True)


def misplaced_option(args: argparse.Namespace) -> str | None:
    """A message for a global option given before a subcommand that does not take it, or None.

    ``sj300 --url X simulate``: the option would be dropped (or overwritten by
    the subcommand's own option of the same name) without a word.
    """
    for option, dest in getattr(args, _GIVEN_BEFORE, ()):
        takes = getattr(args, "takes_json" if dest == "json" else "takes_bus_options", False)
        if not takes:
            command = command_name(args)
            return f"{option} does not apply to `{command}`"
    return None


def add_node_option(parser: argparse.ArgumentParser, *, default: int | None = 1) -> None:
    """Add ``-n/--node``."""
    shown = f"default {default}" if default is not None else "default: the file's node"
    parser.add_argument(
        "-n", "--node", type=node_number, default=default, metavar="N", help=f"drive ({shown})"
    )


def add_json_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--json`` (a global option: also before the subcommand)."""
    default = argparse.SUPPRESS if isinstance(parser, GlobalOptionsOnParent) else False
    parser.add_argument(
        "--json",
        action="store_true",
        default=default,
        help="print JSON (keys are the result field names)",
    )
    parser.set_defaults(takes_json=True)


def command_name(args: argparse.Namespace) -> str:
    """The subcommand as the user wrote it: ``status``, ``params restore``."""
    name: str = getattr(args, "command_name", None) or getattr(args, "command", None) or "sj300"
    return name


def bus_url(args: argparse.Namespace) -> str | None:
    """``--url``, else ``--sim``'s or ``$SJ300_URL``, else the subcommand's default (None: none).

    Raises:
        CliError: both ``--url`` and ``--sim``.
    """
    if getattr(args, "sim", False):
        if args.url:
            raise CliError("give --url or --sim, not both")
        default: str | None = args.default_url
        return default
    url: str | None = args.url or os.environ.get(ENV_URL) or args.default_url
    return url


def implicit_bus(args: argparse.Namespace) -> bool:
    """True when nothing names the bus: no ``--url``, no ``--sim``, no ``$SJ300_URL``."""
    return not (args.url or getattr(args, "sim", False) or os.environ.get(ENV_URL))


def line_settings(args: argparse.Namespace, url: str) -> LineSettings | None:
    """The line settings from the options over the URL's; None when no option is given.

    Raises:
        LocalProtocolError: a bad URL or setting.
    """
    given = (args.baud, args.parity, args.bytesize, args.stopbits)
    if all(v is None for v in given):
        return None
    base = parse_bus_url(url, protocol=getattr(args, "protocol", None)).line or LineSettings()
    return LineSettings.parse(
        base.baudrate if args.baud is None else args.baud,
        base.bytesize if args.bytesize is None else args.bytesize,
        base.parity if args.parity is None else args.parity,
        base.stopbits if args.stopbits is None else args.stopbits,
    )


#: What a command may need beyond the common reads and commands (a
#: :class:`~sj300_async.profiles.Capabilities` field), and its name in a refusal.
NEEDS: Final = {
    "trip_history": "a trip history",
    "broadcast_stop": "a broadcast stop",
    "store": "storing settings apart",
    "parameter_backup": "a parameter backup format",
}


def profile_of(bus: Bus) -> Profile:
    """The profile of *bus*'s protocol.

    Raises:
        LocalProtocolError: the protocol has none (the commands cannot serve it).
    """
    return get_profile(bus.dialect.name)


def cli_profile(args: argparse.Namespace, url: str | None = None) -> Profile:
    """The profile of the drives the command will talk to, before its bus is open.

    The shell's bus's when it lends one, else the protocol the options and
    the URL name (the default protocol when neither does).

    Raises:
        LocalProtocolError: a bad URL, or a protocol without a profile.
        CliError: both ``--url`` and ``--sim``.
    """
    lent = lent_bus()
    if lent is not None:
        return profile_of(lent)
    return _profile_named(args, url or bus_url(args) or DEFAULT_URL)


def _profile_named(args: argparse.Namespace, url: str) -> Profile:
    """The profile of the protocol the options and *url* name (before any bus is open)."""
    protocol = getattr(args, "protocol", None)
    return get_profile(
        protocol or parse_bus_url(url, protocol=protocol).protocol or DEFAULT_PROTOCOL
    )


def require(args: argparse.Namespace, profile: Profile, needs: str | None) -> None:
    """Refuse, before anything is sent, what *profile*'s drives cannot do or be.

    Raises:
        CliError: ``-n`` outside the protocol's range, or a capability it lacks (exit 2).
    """
    node = getattr(args, "node", None)
    low, high = profile.node_range
    if isinstance(node, int) and not low <= node <= high:
        noun = profile.node_noun
        raise CliError(f"argument -n/--node: a {noun} is {low}..{high}, got '{node}' (see --help)")
    if needs is not None and not getattr(profile.capabilities, needs):
        raise CliError(
            f"{command_name(args)} needs {NEEDS[needs]}, which {profile.model} drives "
            f"(protocol {profile.name}) do not have here"
        )


@asynccontextmanager
async def open_cli_bus(
    args: argparse.Namespace, url: str | None = None, *, needs: str | None = None
) -> AsyncIterator[Bus]:
    """Open the bus the options name (or *url*), closed on exit.

    Args:
        needs: a capability the command needs of the drives' protocol (a
            :data:`NEEDS` key); a protocol without it is refused before
            anything is opened.

    Raises:
        CliError: a node outside the protocol's range, or a capability it lacks.
        LocalProtocolError: a bad URL or setting, or a protocol without a profile.
        TransportError: the bus cannot be reached.
    """
    lent = lent_bus()
    if lent is not None:  # in `sj300 shell`: its bus, which stays open
        require(args, profile_of(lent), needs)
        with _tracing(lent, args, asyncio.get_running_loop().time()):
            yield lent
        return
    started = asyncio.get_running_loop().time()
    command = command_name(args)
    implicit = implicit_bus(args)
    url = url or bus_url(args) or DEFAULT_URL
    require(args, _profile_named(args, url), needs)
    if implicit and command in CHANGES_DRIVES:
        raise CliError(
            f"{command} changes drives: say which bus with --url URL or ${ENV_URL}, "
            "or --sim for the in-memory simulator"
        )
    retries = getattr(args, "retries", None)
    async with open_bus(
        url,
        timeout=args.timeout,
        retries=getattr(args, "default_retries", 2) if retries is None else retries,
        line=line_settings(args, url),
        protocol=getattr(args, "protocol", None),
        capture=getattr(args, "capture", None),
    ) as bus:
        if implicit:
            note = f"no --url given: these are simulated drives ({url})"
            print(f"sj300 {command}: note: {note}", file=sys.stderr, flush=True)
            simulated_output.set(True)  # print_json marks JSON objects from here on
        with _tracing(bus, args, started):
            yield bus


@contextmanager
def _tracing(bus: Bus, args: argparse.Namespace, started: float) -> Iterator[None]:
    """With ``--trace``: every frame on stderr while within, timed from *started* (loop time).

    The bus's own hook is put back after (a shell's bus outlives the command).
    """
    if not getattr(args, "trace", False):
        yield
        return
    from ._trace import FrameTracer

    previous = bus.trace
    bus.trace = FrameTracer(bus.dialect, started)
    try:
        yield
    finally:
        bus.trace = previous
