"""``sj300 trips --record DIR``: the gateway's trip black box, for a plant without a gateway.

It polls a line as the gateway does (``--nodes``, ``--interval``) and keeps a
record of every new trip in *DIR*: one JSON and one pcapng each, the same
files and the same pruning as the gateway's ``[recorder]`` (docs/guide/trips.md).
One line per record on stdout (its JSON object with ``--json``); it runs until
Ctrl-C (exit 130) or ``--count`` records.

Decisions:

- **It is a gateway with no door.** The same core polls, keeps the trends
  and the line's frames and makes the records: a record made here and one
  made by a gateway cannot differ, and nothing is written to a drive.
- Records already in *DIR* are kept (and pruned with the new ones): the
  directory may be a gateway's, copied off the edge box.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

from ._common import bus_url
from ._errors import CliError
from ._output import print_json
from ._session import run_async

if TYPE_CHECKING:
    from ..gateway import GatewayConfig
    from ..gateway.recorder import RecordSummary

__all__ = ["add_record_options", "record"]


def add_record_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--record`` and its settings to ``sj300 trips``."""
    group = parser.add_argument_group("recording (--record)")
    group.add_argument(
        "--record",
        type=Path,
        metavar="DIR",
        help="watch the line and keep a record of every new trip in DIR (JSON and pcapng)",
    )
    group.add_argument("--nodes", default="1", metavar="LIST", help="drives to watch (default 1)")
    group.add_argument(
        "--interval", type=float, default=0.5, metavar="S", help="poll interval (default 0.5)"
    )
    group.add_argument(
        "--before", type=float, default=60.0, metavar="S", help="seconds kept before a trip (60)"
    )
    group.add_argument(
        "--after", type=float, default=10.0, metavar="S", help="seconds kept after a trip (10)"
    )
    group.add_argument("--count", type=int, metavar="N", help="stop after N records")
    group.add_argument("--max-records", type=int, default=1000, metavar="N",
                       help="records kept in DIR, the oldest pruned first (1000)")  # fmt: skip


def record(args: argparse.Namespace) -> int:
    """Watch the line, keep the records; return 0 after ``--count`` of them."""
    if args.count is not None and args.count < 1:
        raise CliError("--count: expected at least 1")
    for name in ("before", "after"):
        if not 0 <= getattr(args, name) <= 3600:
            raise CliError(f"--{name}: expected 0..3600 seconds")
    if not args.interval > 0:
        raise CliError("--interval: expected more than 0 seconds")
    if args.max_records < 1:
        raise CliError("--max-records: expected at least 1")
    # Here, not at import: every other command starts without the gateway's modules.
    from ..gateway import GatewayConfigError, config_from_flags
    from ..gateway.recorder import RecorderConfig

    url = bus_url(args)
    if url is None:
        raise CliError("give --url (or --sim)")
    try:
        config = config_from_flags(
            url=url, nodes=args.nodes, protocol=args.protocol, interval_s=args.interval
        )
    except GatewayConfigError as exc:
        raise CliError(str(exc)) from None
    recorder = RecorderConfig(
        directory=args.record,
        before_s=args.before,
        after_s=args.after,
        max_records=args.max_records,
    )
    return run_async(_watch(dataclasses.replace(config, recorder=recorder), args))


async def _watch(config: GatewayConfig, args: argparse.Namespace) -> int:
    from ..gateway import Gateway

    done = asyncio.Event()
    kept = 0

    def show(summary: RecordSummary) -> None:
        nonlocal kept
        kept += 1
        if args.json:
            print_json(summary.as_json())
        else:
            trip = " ".join(filter(None, (summary.code, summary.meaning))) or "a trip"
            print(f"{summary.line} {summary.node}: {trip} -> {args.record / summary.id}.json",
                  flush=True)  # fmt: skip
        if args.count is not None and kept >= args.count:
            done.set()

    async with Gateway(config) as gateway:
        assert gateway.recorder is not None
        gateway.recorder.listeners.append(show)
        await done.wait()
    return 0
