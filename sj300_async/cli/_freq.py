"""``sj300 freq HZ``: set a drive's output frequency.

HZ has a resolution of 0.01 Hz. A refusal is explained the way the drive's
profile knows it (SJ300: NAK 13, the frequency source A001 must be 03;
NAK 16, above the maximum frequency A004).

JSON: ``{"node": 1, "frequency_hz": 30.0}``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..wire import NakError
from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus, profile_of
from ._errors import FAILURE, CliError
from ._output import print_json
from ._session import run_async

__all__ = ["add_parser"]


def _hertz(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"HZ must be a number, got {text!r}") from None


def add_parser(subparsers: Any) -> None:
    """Add ``freq`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "freq",
        help="set the output frequency",
        description="Set the output frequency (SJ300 command 01, FR-700 HED).",
    )
    p.add_argument("hz", type=_hertz, metavar="HZ", help="frequency in Hz, e.g. 42.5")
    add_node_option(p)
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Send the frequency; return 0."""
    return run_async(_freq(args))


async def _freq(args: argparse.Namespace) -> int:
    async with open_cli_bus(args) as bus:
        noun = profile_of(bus).node_noun
        try:
            await bus.drive(args.node).set_frequency(args.hz)
        except NakError as exc:
            hint = profile_of(bus).nak_hint(exc.code, "frequency")
            if hint is None:
                raise
            raise CliError(f"{args.hz:g} Hz: {exc}: {hint}", status=FAILURE) from None
    if args.json:
        print_json({"node": args.node, "frequency_hz": args.hz})
    else:
        print(f"{noun} {args.node:02d}: frequency set to {args.hz:.2f} Hz")
    return 0
