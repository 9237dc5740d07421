"""``sj300 scan``: which nodes (FR-700: stations) answer.

By default the protocol's whole address range (SJ300 nodes 1..32, FR-700
stations 0..31). Each node gets one status request without retries, at the
computed time-out (the line's wire time plus 50 ms, 100 ms over TCP) unless
``--timeout`` says otherwise; a missing node costs about twice that, its
time-out and the quiet period after it. Any answer counts, a NAK too.
Progress goes to stderr: a bar on a terminal, else a line per node
(``node 03: answers``, ``node 09: no answer``).

Prints ``nodes answering: 1-8 (8 of 32)``; exits 1 when no node answers
(like grep finding nothing).

JSON: ``{"scanned": [1, ..., 32], "answering": [1, ..., 8]}``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from ..bus import Bus, parse_node_list
from ..wire import LocalProtocolError, NakError, RemoteProtocolError, ReplyTimeoutError
from ._args import format_nodes
from ._common import add_bus_options, add_json_option, cli_profile, open_cli_bus
from ._errors import FAILURE, CliError
from ._output import is_terminal, print_json
from ._session import run_async

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> None:
    """Add ``scan`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "scan",
        help="find the nodes that answer",
        description="Ask every node for its status once and list the nodes that answer.",
    )
    p.add_argument(
        "--nodes",
        metavar="LIST",
        help="nodes to try, e.g. 1-8,12 (default: the protocol's range, SJ300 1-32, "
        "FR-700 stations 0-31)",
    )
    add_json_option(p)
    add_bus_options(p, retries=0)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Scan; return 0 when a node answers, 1 when none does."""
    return run_async(_scan(args))


async def probe(bus: Bus, node: int) -> bool:
    """True when *node* answers anything (a NAK or a damaged reply is an answer too).

    Raises:
        TransportError: the link failed (a scan cannot go on).
    """
    try:
        await bus.drive(node).read_status()
    except ReplyTimeoutError:
        return False
    except (NakError, RemoteProtocolError):
        return True
    return True


async def _scan(args: argparse.Namespace) -> int:
    profile = cli_profile(args)
    low, high = profile.node_range
    noun = profile.node_noun
    nodes = list(range(low, high + 1))
    if args.nodes is not None:
        try:
            nodes = list(parse_node_list(args.nodes, low=low, high=high, noun=noun))
        except LocalProtocolError as exc:
            raise CliError(f"argument --nodes: {exc}") from None
    async with open_cli_bus(args) as bus:
        if is_terminal(sys.stderr):
            answering = await _with_progress_bar(bus, nodes, noun)
        else:
            answering = await _probe_all(bus, nodes, _plain_progress(noun))
    if args.json:
        print_json({"scanned": nodes, "answering": answering})
    elif answering:
        count = f"{len(answering)} of {len(nodes)}"
        print(f"{noun}s answering: {format_nodes(answering)} ({count})")
    else:
        print(f"no {noun} answers (tried {format_nodes(nodes)})")
    return 0 if answering else FAILURE


async def _probe_all(bus: Bus, nodes: list[int], advance: Callable[[int, bool], None]) -> list[int]:
    answering = []
    for node in nodes:
        found = await probe(bus, node)
        if found:
            answering.append(node)
        advance(node, found)
    return answering


def _plain_progress(noun: str) -> Callable[[int, bool], None]:
    def advance(node: int, found: bool) -> None:
        answer = "answers" if found else "no answer"
        print(f"{noun} {node:02d}: {answer}", file=sys.stderr, flush=True)

    return advance


async def _with_progress_bar(bus: Bus, nodes: list[int], noun: str) -> list[int]:
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    progress = Progress(
        TextColumn(f"scanning {noun} {{task.fields[node]:>2}}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[found]} answering"),
        console=Console(stderr=True),
        transient=True,
    )
    with progress:
        task = progress.add_task("scan", total=len(nodes), node=nodes[0], found=0)
        count = 0

        def advance(node: int, found: bool) -> None:
            nonlocal count
            count += found
            progress.update(task, advance=1, node=node, found=count)

        return await _probe_all(bus, nodes, advance)
