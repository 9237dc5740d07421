"""``sj300 reset``: clear a drive's trip the way the manuals allow over the line.

The drive's profile sends the reset (:meth:`~sj300_async.profiles.Profile.reset`):

- SJ300: the RS (reset) intelligent input through command 02: RS on, then
  every command-02 input off (``set_terminals(0)``; an input held through
  command 02, such as FW, is released too).
- FR-700 (``--protocol fr700``): the inverter reset, HFD H9696. The drive
  sends no reply and restarts (about a second on a real one), answering
  nothing meanwhile: the status is polled until it answers again.

First the status is read: a drive that is not tripped gets nothing that
changes it ("not tripped", exit 0). Otherwise the trip is named from the
drive's history (SJ300 ``E07 over-voltage``; FR-700 ``E.OC1 overcurrent trip
during acceleration``), the reset is sent, and the status is polled
until the trip is gone or ``--wait`` seconds have passed. Exit 0 when the
trip cleared, 1 when the drive is still tripped (or never answered again).

JSON: ``{"node": 1, "was_tripped": true, "trip": {"code": "E07", "number":
7, "name": "OVER_VOLTAGE", "meaning": "over-voltage"}}`` (``"trip": null``
when the drive was not tripped, or its history holds nothing).
"""

from __future__ import annotations

import argparse
import asyncio
from typing import Any

from ..profiles import Profile, Trip
from ..wire import ReplyTimeoutError
from ._common import (
    add_bus_options,
    add_json_option,
    add_node_option,
    open_cli_bus,
    positive_float,
    profile_of,
)
from ._errors import FAILURE, CliError
from ._output import print_json
from ._session import run_async
from ._tripinfo import trip_or_none

__all__ = ["add_parser"]

#: Time between two status reads while waiting for the trip to clear.
_POLL_S = 0.1


def add_parser(subparsers: Any) -> None:
    """Add ``reset`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "reset",
        help="clear a drive's trip",
        description="Clear a drive's trip: SJ300 with the RS input (command 02), FR-700 with "
        "the inverter reset (HFD H9696). Nothing is sent to a drive that is not tripped; "
        "exit 1 when the trip does not clear.",
    )
    add_node_option(p)
    p.add_argument(
        "--wait",
        type=positive_float,
        default=5.0,
        metavar="SECONDS",
        help="how long the trip may take to clear (default 5; an FR-700 restarts)",
    )
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Reset the trip of ``--node``; return 0 when it cleared or there was none."""
    return run_async(_reset(args))


async def _reset(args: argparse.Namespace) -> int:
    node: int = args.node
    async with open_cli_bus(args) as bus:
        profile = profile_of(bus)
        drive = bus.drive(node)
        if not profile.status_view(await drive.read_status()).tripped:
            _report(args, profile, was_tripped=False, trip=None)
            return 0
        trip = await trip_or_none(profile, drive)
        await profile.reset(drive)
        await _until_cleared(profile, drive, node, trip, args.wait)
    _report(args, profile, was_tripped=True, trip=trip)
    return 0


async def _until_cleared(
    profile: Profile, drive: Any, node: int, trip: Trip | None, wait_s: float
) -> None:
    """Read the status until the trip is gone.

    Raises:
        CliError: still tripped, or no answer, after *wait_s*.
    """
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    answered = False
    while True:
        try:
            status = await drive.read_status()
        except ReplyTimeoutError:  # an FR-700 restarting after its reset
            pass
        else:
            answered = True
            if not profile.status_view(status).tripped:
                return
        if loop.time() >= deadline:
            break
        await asyncio.sleep(_POLL_S)
    noun = profile.node_noun
    if not answered:
        raise CliError(
            f"{noun} {node:02d} did not answer after the reset (waited {wait_s:g} s)",
            status=FAILURE,
        )
    what = f": {trip}" if trip is not None else ""
    raise CliError(f"{noun} {node:02d} is still tripped after the reset{what}", status=FAILURE)


def _report(
    args: argparse.Namespace, profile: Profile, *, was_tripped: bool, trip: Trip | None
) -> None:
    node: int = args.node
    noun = profile.node_noun
    if args.json:
        print_json(
            {
                "node": node,
                "was_tripped": was_tripped,
                "trip": None if trip is None else trip.as_json(),
            }
        )
    elif not was_tripped:
        print(f"{noun} {node:02d} is not tripped: nothing to reset")
    elif trip is None:
        print(f"{noun} {node:02d}: reset, the trip cleared")
    else:
        print(f"{noun} {node:02d}: reset, {trip} cleared")
