"""``sj300 monitor``: a live view of many drives, polled by :class:`~sj300_async.Poller`.

Without ``--url`` and without ``SJ300_URL`` it is a demo: an in-memory bus
of eight simulated drives that :mod:`._demo` keeps busy (ramping, reversing,
one tripping now and then and being reset).

Which drives: ``--nodes``; without it, on a real bus (a serial port, a TCP
bridge: not ``sim://``) the monitor first scans the protocol's whole node
range (a progress bar on a terminal's stderr, one status request per node
without retries, as ``sj300 scan``) and monitors the nodes that answered
(none: one line, exit 1); on ``sim://`` the simulated drives (the demo's
1-8).

Output, by where stdout goes:

- a terminal: a table refreshing in place (rich ``Live``), one row per
  drive. Its columns fit the terminal's width: from 100 columns node, state,
  set frequency (F001), output frequency, current, voltage, torque, power,
  last error, latency and link (the widest of these layouts that fits);
  below 100 a compact one: node, state, set and output frequency, current,
  voltage, link. The node and frequency columns are never cut; the state
  column is (with ``…``) when the room runs out;
- anything else: one plain line per drive per poll, for logs;
- ``--json`` (either way): one JSON object per sample per line, flushed:
  a :class:`~._record.DriveRecord`, the record the fleet view prints too
  (the drive model's names; ``time`` the sample's, in Unix seconds).

Each sample becomes a :class:`~sj300_async.profiles.DriveSnapshot` built by
the drive's profile, and the rows show the snapshot: states read as a person
would (``stopped``, ``accelerating``, ``running``, ``tripped``), the set
frequency (SJ300 F001 in the poll; an FR-700's read beside it, see
:mod:`._board`), torque and power where the protocol measures them. A tripped drive's row names its
trip (``tripped E07 over-voltage``; an FR-700 ``tripped E.OC1 overcurrent
trip during acceleration``, or ``tripped fault H9A`` for a byte its table
lacks), read once per trip from the drive's history by its profile. A
drive that has never answered is ``offline`` (:attr:`~sj300_async.Sample.answered`); one that
stops answering turns offline and is probed every few seconds instead of
being polled; the monitor itself never stops for a failing drive or a
dropped link.

With ``--url mqtt://HOST:PORT[/prefix]`` (or ``mqtts://``) it opens no bus
and shows the fleet instead: every drive of every gateway on the broker
(:mod:`._fleet`).

It runs until Ctrl-C (exit 130, as for any command), SIGTERM (exit 0),
``--count`` cycles or ``--duration`` seconds. A cycle is one sample of every
drive, on a bus as on a broker (:data:`COUNT_HELP`): on a bus, of every node
(a node set aside as offline between its probes is not waited for).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from collections.abc import Coroutine
from typing import Any, Final

from .. import Poller, Sample
from ..bus import Bus, parse_bus_url
from ._args import format_nodes, parse_any_nodes
from ._board import Board
from ._common import (
    add_bus_options,
    add_json_option,
    bus_url,
    open_cli_bus,
    positive_float,
    profile_of,
)
from ._demo import DEMO_URL, demo_running
from ._errors import FAILURE, CliError
from ._output import is_terminal, print_json
from ._progress import progress
from ._scan import probe
from ._session import run_async

__all__ = ["add_parser"]

_log = logging.getLogger("sj300_async.cli.monitor")

#: The nodes polled on a ``sim://`` bus whose simulated drives are not known.
_DEFAULT_NODES: Final = tuple(range(1, 9))
#: Exit status of Ctrl-C (SIGINT), as for every command.
INTERRUPTED: Final = 130
#: What ``--count`` counts, on a bus and on a broker alike.
COUNT_HELP: Final = (
    "stop after N cycles, a cycle being one sample of every drive (N samples of each): on a "
    "bus every node polled once (a node set aside as offline is not waited for); on "
    "mqtt:// the states the broker hands over on subscribing, then one new state of every "
    "drive whose gateway and the drive itself are online"
)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return value


def add_parser(subparsers: Any) -> None:
    """Add ``monitor`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "monitor",
        help="live view of the drives (a demo of 8 simulated drives without --url)",
        description="Poll drives and show their state live. Without --url or $SJ300_URL: "
        "a demo of eight simulated drives. On a real bus without --nodes, the nodes a scan "
        "finds. With --url mqtt://HOST:PORT[/prefix]: every drive of every gateway publishing "
        "on that broker (read-only). Ctrl-C stops it (exit 130).",
    )
    p.add_argument(
        "--nodes",
        type=parse_any_nodes,
        metavar="LIST",
        help="drives to poll, e.g. 1-4,7 (default: on a real bus the nodes a scan finds, "
        "else the simulated ones, 1-8)",
    )
    p.add_argument(
        "--interval",
        type=positive_float,
        default=0.5,
        metavar="SECONDS",
        help="time between polls of a drive (default 0.5)",
    )
    p.add_argument(
        "--count",
        type=_positive_int,
        metavar="N",
        help=COUNT_HELP,
    )
    p.add_argument("--duration", type=positive_float, metavar="SECONDS", help="stop after this")
    add_json_option(p)
    add_bus_options(p, default_url=None)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Monitor until done (0) or interrupted by Ctrl-C (130)."""
    try:
        return run_async(_monitor(args))
    except KeyboardInterrupt:
        return INTERRUPTED


async def _monitor(args: argparse.Namespace) -> int:
    url = bus_url(args)
    if url is not None and _is_fleet_url(url):  # a broker, not a bus: the fleet view
        from ._fleet import watch_fleet  # here: every sj300 command imports this module

        await _until_terminated(watch_fleet(args, url))
        return 0
    nodes: list[int] | None = args.nodes
    if nodes is None and url is not None and _real_bus(args, url):
        nodes = await _scan_first(args, url)
    async with open_cli_bus(args, url or DEMO_URL) as bus:
        if nodes is None:
            nodes = await _simulated_or_scanned(args, bus)
        profile = profile_of(bus)
        setpoint = profile.setpoint_parameter
        poller = Poller(
            interval_s=args.interval, parameters=() if setpoint is None else (setpoint,)
        )
        poller.add(bus, nodes)
        # Subscribed before polling starts, so not even the first sample is missed.
        # Unbounded: printing waits only for the reads beside the poll (one attempt
        # each, on the same line), which hold the poller back as much as the printing.
        samples: asyncio.Queue[Sample] = asyncio.Queue()
        poller.on_sample(samples.put_nowait)
        board = Board(bus, profile, nodes, demo=url is None)
        async with poller, demo_running([bus] if url is None else []):
            try:
                with board.live(enabled=is_terminal() and not args.json):
                    await _until_terminated(_consume(args, poller, bus, samples, board))
            finally:
                board.close()
    return 0


def _is_fleet_url(url: str) -> bool:
    """True when *url* names a broker (``mqtt://``, ``mqtts://``): the fleet view, not a bus."""
    scheme, sep, _ = url.partition("://")
    return bool(sep) and scheme.lower() in ("mqtt", "mqtts")


def _real_bus(args: argparse.Namespace, url: str) -> bool:
    """True for a serial port or a TCP bridge, False for ``sim://``.

    Raises:
        LocalProtocolError: a bad URL.
    """
    return parse_bus_url(url, protocol=getattr(args, "protocol", None)).scheme != "sim"


async def _scan_first(args: argparse.Namespace, url: str) -> list[int]:
    """Scan the protocol's node range on a bus of its own without retries, as ``sj300 scan``.

    Raises:
        CliError: no node answers (exit 1).
        TransportError: the bus cannot be reached.
    """
    scan_args = argparse.Namespace(**{**vars(args), "retries": 0})
    async with open_cli_bus(scan_args, url) as bus:
        return await _scan(bus)


async def _simulated_or_scanned(args: argparse.Namespace, bus: Bus) -> list[int]:
    """The simulated drives of a ``sim://`` bus; any other bus (a shell's) is scanned."""
    if bus.simulator is None:
        return await _scan(bus)
    drives = getattr(bus.simulator, "drives", None)
    return sorted(drives) if drives else list(_DEFAULT_NODES)


async def _scan(bus: Bus) -> list[int]:
    low, high = bus.dialect.node_range
    candidates = list(range(low, high + 1))
    found: list[int] = []
    with progress("scanning node", len(candidates)) as advance:
        for node in candidates:
            if await probe(bus, node):
                found.append(node)
            advance(f"{node:02d}")
    if not found:
        raise CliError(
            f"no node answers on {bus.description} (scanned {format_nodes(candidates)})",
            status=FAILURE,
        )
    print(
        f"sj300 monitor: nodes answering: {format_nodes(found)} "
        f"({len(found)} of {len(candidates)})",
        file=sys.stderr,
        flush=True,
    )
    return found


async def _until_terminated(work: Coroutine[Any, Any, None]) -> None:
    """Run *work* until it ends or SIGTERM comes (then cancel it and return normally).

    SIGINT needs nothing: asyncio.run turns it into KeyboardInterrupt after
    cleaning up, and :func:`run` makes that exit 130.
    """
    loop = asyncio.get_running_loop()
    task = asyncio.ensure_future(work)
    try:
        loop.add_signal_handler(signal.SIGTERM, task.cancel)
    except (NotImplementedError, RuntimeError):  # not on this platform / thread
        await task
        return
    try:
        await task
    except asyncio.CancelledError:
        if not task.cancelled() or _current_cancelling():
            raise  # we were cancelled ourselves, not by SIGTERM
    finally:
        loop.remove_signal_handler(signal.SIGTERM)
        task.cancel()


def _current_cancelling() -> int:
    current = asyncio.current_task()
    return current.cancelling() if current is not None else 0


async def _consume(
    args: argparse.Namespace,
    poller: Poller,
    bus: Bus,
    samples: asyncio.Queue[Sample],
    board: Board,
) -> None:
    cycles = 0
    pending = set(board.nodes)  # the nodes not sampled yet this cycle
    with contextlib.suppress(TimeoutError):  # --duration is up
        async with asyncio.timeout(args.duration):
            while args.count is None or cycles < args.count:
                sample = await samples.get()
                board.update(sample)
                if not board.is_live:  # a line is final: with its trip and set frequency
                    await board.settle(sample.node)
                if args.json:
                    print_json(board.record(sample).as_json())
                elif not board.is_live:
                    print(board.plain_line(sample), flush=True)
                pending.discard(sample.node)
                # A node the poller has set aside as offline is probed only now and then:
                # the cycle does not wait for it.
                if not any(poller.health(bus, node).online for node in pending):
                    cycles += 1
                    pending = set(board.nodes)
