"""``sj300 freq HZ``: set a drive's output frequency (command 01; the drive needs A001 = 03).

HZ has a resolution of 0.01 Hz; the drive refuses (NAK 16) a frequency
above its maximum A004.

JSON: ``{"node": 1, "frequency_hz": 30.0}``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..sj300._codes import NakCode
from ..wire._errors import NakError
from ._common import add_bus_options, add_json_option, add_node_option, open_cli_bus
from ._errors import FAILURE, CliError
from ._output import print_json
from ._session import run_async

__all__ = ["add_parser"]

_HINTS: dict[int, str] = {
    NakCode.EXECUTION_DISABLED: "the frequency source A001 must be 03 (serial)",
    NakCode.ABNORMAL_PARAMETER: "above the maximum frequency A004?",
}


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
        description="Set the output frequency (command 01).",
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
        try:
            await bus.drive(args.node).set_frequency(args.hz)
        except NakError as exc:
            hint = _HINTS.get(exc.code)
            if hint is None:
                raise
            raise CliError(f"{args.hz:g} Hz: {exc}: {hint}", status=FAILURE) from None
    if args.json:
        print_json({"node": args.node, "frequency_hz": args.hz})
    else:
        print(f"node {args.node:02d}: frequency set to {args.hz:.2f} Hz")
    return 0
