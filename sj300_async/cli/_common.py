"""What every bus subcommand shares: where the bus is, how to talk to it, which drive.

``--url`` picks the transport (see :func:`sj300_async.parse_bus_url`); without
it, the ``SJ300_URL`` environment variable; without that, :data:`DEFAULT_URL`,
an in-memory simulator of eight drives, so every command works out of the
box. That simulator lives only as long as the command: nothing done by one
invocation of ``sim://`` (a run command, a parameter write) is seen by the
next. Point several commands at one ``sj300 simulate`` over ``tcp://`` to
keep state between them.

``--baud``, ``--parity``, ``--bytesize`` and ``--stopbits`` are the line
settings, the same as the URL's ``baudrate=...`` query (and they win over
it). On a serial port they configure the UART; over ``tcp://`` they
describe the RS-485 line behind the bridge, which sets the computed reply
time-outs; on ``sim://`` they are the simulated line's speed, paced with
``pace=1``. Settings not given keep the URL's, else 19200 8N1.

``--protocol fr700`` (or ``protocol=fr700`` in the URL) talks to Mitsubishi
FR-700 drives (stations 0..31); the commands written for SJ300 parameters
and terminals refuse it, ``monitor`` shows either.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Final

from ..bus import Bus, open_bus
from ..bus._url import parse_bus_url
from ..sj300._constants import MAX_NODE, MIN_NODE
from ..wire._errors import LocalProtocolError
from ..wire._line import LineSettings
from ._session import lent_bus

__all__ = [
    "DEFAULT_URL",
    "ENV_URL",
    "add_bus_options",
    "add_json_option",
    "add_node_option",
    "bus_url",
    "node_number",
    "open_cli_bus",
    "positive_float",
]

#: The environment variable that gives the bus URL when ``--url`` does not.
ENV_URL: Final = "SJ300_URL"
#: The bus when neither ``--url`` nor ``SJ300_URL`` is given: a fresh in-memory simulator.
DEFAULT_URL: Final = "sim://?nodes=1-8"


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
    """argparse type: a node address 1..32."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not MIN_NODE <= value <= MAX_NODE:
        raise argparse.ArgumentTypeError(f"a node is {MIN_NODE}..{MAX_NODE}, got {text!r}")
    return value


def add_bus_options(
    parser: argparse.ArgumentParser,
    *,
    default_url: str | None = DEFAULT_URL,
    retries: int = 2,
) -> None:
    """Add ``--url``, ``--timeout``, ``--retries`` and the line settings to *parser*."""
    bus = parser.add_argument_group("bus")
    fallback = default_url or "the built-in demo"
    where = f"default ${ENV_URL}, else {fallback}"
    bus.add_argument(
        "--url",
        metavar="URL",
        help=f"tcp://HOST:PORT, /dev/ttyUSB0, serial://PATH?baudrate=..., sim://?nodes=1-8 "
        f"({where}; sim:// keeps no state between commands)",
    )
    bus.add_argument(
        "--timeout",
        type=positive_float,
        metavar="SECONDS",
        help="reply time-out (default: computed from the line speed)",
    )
    bus.add_argument(
        "--retries",
        type=_retries,
        default=retries,
        metavar="N",
        help=f"attempts after the first on a time-out or a damaged reply (default {retries})",
    )
    bus.add_argument(
        "--protocol",
        choices=("sj300", "fr700"),
        help="the drives' protocol (default: the URL's protocol=, else sj300)",
    )
    line = parser.add_argument_group(
        "line settings",
        "a serial port's UART; for tcp:// the line behind the bridge (time-outs); "
        "the URL's query otherwise, else 19200 8N1",
    )
    line.add_argument("--baud", type=int, metavar="BPS", help="line speed")
    line.add_argument("--parity", type=str.upper, choices=("N", "E", "O"))
    line.add_argument("--bytesize", type=int, choices=(7, 8))
    line.add_argument("--stopbits", type=int, choices=(1, 2))
    parser.set_defaults(default_url=default_url)


def add_node_option(parser: argparse.ArgumentParser, *, default: int | None = 1) -> None:
    """Add ``-n/--node``."""
    shown = f"default {default}" if default is not None else "default: the file's node"
    parser.add_argument(
        "-n", "--node", type=node_number, default=default, metavar="N", help=f"drive ({shown})"
    )


def add_json_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--json``."""
    parser.add_argument(
        "--json", action="store_true", help="print JSON (keys are the result field names)"
    )


def bus_url(args: argparse.Namespace) -> str | None:
    """``--url``, else ``$SJ300_URL``, else the subcommand's default (None: none)."""
    url: str | None = args.url or os.environ.get(ENV_URL) or args.default_url
    return url


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


@asynccontextmanager
async def open_cli_bus(
    args: argparse.Namespace, url: str | None = None, *, any_protocol: bool = False
) -> AsyncIterator[Bus]:
    """Open the bus the options name (or *url*), closed on exit.

    Args:
        any_protocol: accept a URL of any protocol (``protocol=fr700``); by
            default the bus must speak SJ300, as the SJ300 commands need.

    Raises:
        LocalProtocolError: a bad URL or setting, or another protocol.
        TransportError: the bus cannot be reached.
    """
    lent = lent_bus()
    if lent is not None:  # in `sj300 shell`: its bus, which stays open
        if not any_protocol and lent.dialect.name != "sj300":
            raise LocalProtocolError(
                f"this command works with SJ300 drives only, not {lent.dialect.name}"
            )
        yield lent
        return
    url = url or bus_url(args) or DEFAULT_URL
    protocol = getattr(args, "protocol", None)
    if not any_protocol:
        if protocol not in (None, "sj300"):
            raise LocalProtocolError(f"this command works with SJ300 drives only, not {protocol}")
        protocol = "sj300"
    async with open_bus(
        url,
        timeout=args.timeout,
        retries=args.retries,
        line=line_settings(args, url),
        protocol=protocol,
    ) as bus:
        yield bus
