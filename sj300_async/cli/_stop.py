"""``sj300 stop``: stop a drive, or with ``--all`` every drive at once (a broadcast, no reply).

A stop goes out before any request already waiting on the bus. ``--all``
needs a protocol with a broadcast (SJ300; the FR-700's computer link has none).

JSON: ``{"node": 1, "broadcast": false}`` (``"node": null`` with ``--all``).
"""

from __future__ import annotations

import argparse
from typing import Any

from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus, profile_of
from ._output import print_json
from ._session import run_async

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> None:
    """Add ``stop`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "stop",
        help="stop a drive (--all: every drive)",
        description="Stop a drive; --all broadcasts the stop to every drive (SJ300).",
    )
    p.add_argument("--all", action="store_true", help="broadcast to every drive (no reply)")
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Send the stop command; return 0."""
    return run_async(_stop(args))


async def _stop(args: argparse.Namespace) -> int:
    async with open_cli_bus(args, needs="broadcast_stop" if args.all else None) as bus:
        noun = profile_of(bus).node_noun
        if args.all:
            await bus.broadcast.stop()
        else:
            await bus.drive(args.node).stop()
    node = None if args.all else args.node
    if args.json:
        print_json({"node": node, "broadcast": args.all})
    else:
        print("all drives: stop (broadcast)" if args.all else f"{noun} {args.node:02d}: stop")
    return 0
