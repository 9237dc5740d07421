"""``sj300 run forward|reverse``: start a drive.

The status is read first: a tripped drive acknowledges a run command and
stays tripped, so the command is refused, naming the trip (exit 1, nothing
sent): clear it with ``sj300 reset``. A refusal is explained the way the
drive's profile knows it (SJ300: NAK 13, the run command source A002 must
be 03).

JSON: ``{"node": 1, "direction": "FORWARD"}``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..wire import Direction, NakError
from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus, profile_of
from ._errors import FAILURE, CliError
from ._output import human, print_json
from ._session import run_async
from ._tripinfo import trip_or_none

__all__ = ["add_parser"]

_DIRECTIONS = {"forward": Direction.FORWARD, "reverse": Direction.REVERSE}


def add_parser(subparsers: Any) -> None:
    """Add ``run`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "run",
        help="run a drive forward or reverse",
        description="Run a drive (SJ300 command 00, FR-700 HFA). Set the frequency with "
        "`sj300 freq`.",
    )
    p.add_argument("direction", choices=sorted(_DIRECTIONS), help="direction of rotation")
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Send the run command; return 0 (a tripped drive: exit 1, nothing sent)."""
    return run_async(_run(args))


async def _run(args: argparse.Namespace) -> int:
    direction = _DIRECTIONS[args.direction]
    async with open_cli_bus(args) as bus:
        profile = profile_of(bus)
        drive = bus.drive(args.node)
        if profile.status_view(await drive.read_status()).tripped:
            trip = await trip_or_none(profile, drive)
            what = f": {trip}" if trip is not None else ""
            raise CliError(
                f"{profile.node_noun} {args.node:02d} is tripped{what}; clear it with sj300 reset",
                status=FAILURE,
            )
        try:
            if direction is Direction.FORWARD:
                await drive.run_forward()
            else:
                await drive.run_reverse()
        except NakError as exc:
            hint = profile.nak_hint(exc.code, "run")
            if hint is None:
                raise
            raise CliError(f"{exc}: {hint}", status=FAILURE) from None
    if args.json:
        print_json({"node": args.node, "direction": direction})
    else:
        print(f"{profile.node_noun} {args.node:02d}: run {human(direction)}")
    return 0
