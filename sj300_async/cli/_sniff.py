"""``sj300 sniff URL``: listen to a line without transmitting; decode, pair, flag.

The URL is what carries the line to us: a TCP tap (``sj300 simulate --tap``,
a bridge port in listen-only use), a serial port on a listen-only RS-485
transceiver or the second port of a socat pair, an RFC 2217 port. Its query
gives the line settings (``?baudrate=9600&parity=E``), which set the
time-outs the sniffer judges by, and the protocol (``--protocol fr700`` or
``protocol=fr700``, with FR-700's ``wait_field`` / ``terminator`` options as
the line uses them).

Output: on a terminal, a live table of the latest frames with the counters
below it; otherwise one line per frame (``--json``: one JSON object per
frame, ``"kind": "frame"``, or per request that went unanswered, ``"kind":
"unanswered"``). ``--capture PATH`` writes every frame to a pcapng file as
well. It runs until Ctrl-C (exit 130), SIGTERM, ``--count N`` frames or
``--duration S`` (exit 0); a summary goes to stderr at the end.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
import time
from collections import deque
from typing import Any, Final

from ..bus import SniffedFrame, Sniffing, Unanswered, protocol_names, sniff
from ._common import add_json_option, positive_float
from ._output import print_json

__all__ = ["add_parser"]

#: Rows the live table keeps.
_ROWS: Final = 20


def add_parser(subparsers: Any) -> None:
    """Add ``sniff`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "sniff",
        help="listen to a line without ever transmitting: decode, pair, flag anomalies",
        description="Listen to an RS-485 line through a tap and decode both directions: "
        "requests paired with their replies, and flags for bad check codes, broken frames, "
        "noise, unanswered requests, late replies, unsolicited replies and two masters "
        "talking. Never writes a byte.",
    )
    p.add_argument(
        "url",
        metavar="URL",
        help="the tap: tcp://HOST:PORT, a serial port, rfc2217://HOST:PORT; line settings "
        "in the query (?baudrate=9600&parity=E)",
    )
    p.add_argument("--protocol", choices=protocol_names(), default=None, help="the line's protocol")
    p.add_argument(
        "--timeout",
        type=positive_float,
        metavar="S",
        help="the master's fixed response time-out (default: computed from the line)",
    )
    p.add_argument("--capture", metavar="PATH", help="also write every frame to a pcapng file")
    p.add_argument("--count", type=int, metavar="N", help="stop after N frames")
    p.add_argument("--duration", type=positive_float, metavar="S", help="stop after S seconds")
    add_json_option(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Listen until stopped; return 0 (130 on Ctrl-C)."""
    return asyncio.run(_listen(args))


async def _listen(args: argparse.Namespace) -> int:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    live = sys.stdout.isatty() and not args.json
    try:
        async with sniff(
            args.url, protocol=args.protocol, timeout=args.timeout, capture=args.capture
        ) as sniffing:
            print(f"listening to {sniffing.description}", file=sys.stderr, flush=True)
            epoch = time.time() - loop.time()  # report times are loop times
            show = _LiveTable(sniffing, epoch) if live else _Lines(args.json, epoch)
            reading = asyncio.create_task(_read(sniffing, show, args.count))
            waiting = [reading, asyncio.create_task(stop.wait())]
            done, pending = await asyncio.wait(
                waiting, timeout=args.duration, return_when=asyncio.FIRST_COMPLETED
            )
            for task in pending:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            for task in done:
                task.result()
            show.close()
            _summary(sniffing)
    finally:
        loop.remove_signal_handler(signal.SIGTERM)
    return 0


async def _read(sniffing: Sniffing, show: _Lines | _LiveTable, count: int | None) -> None:
    frames = 0
    async for report in sniffing.reports():
        show.add(report)
        if isinstance(report, SniffedFrame):
            frames += 1
            if count is not None and frames >= count:
                return


def _summary(sniffing: Sniffing) -> None:
    stats = sniffing.stats
    frames = ", ".join(f"{n} {role}" for role, n in sorted(stats.frames.items())) or "none"
    flagged = ", ".join(f"{n} {what}" for what, n in sorted(stats.anomalies.items())) or "none"
    print(
        f"sj300 sniff: {stats.bytes} bytes, frames: {frames}; paired {stats.paired}; "
        f"flagged: {flagged}",
        file=sys.stderr,
        flush=True,
    )


def _row(report: SniffedFrame | Unanswered, epoch: float) -> dict[str, Any]:
    """A report as JSON-able fields (also the table's columns); ``t`` is Unix time."""
    if isinstance(report, Unanswered):
        request = report.request
        return {
            "kind": "unanswered",
            "t": round(report.time + epoch, 6),
            "request": request.number,
            "node": request.frame.node,
            "summary": request.frame.summary,
            "anomalies": [a.value for a in report.anomalies],
        }
    frame = report.frame
    return {
        "kind": "frame",
        "n": report.number,
        "t": round(report.time + epoch, 6),
        "role": frame.role.value,
        "node": frame.node,
        "summary": frame.summary,
        "hex": frame.data.hex(" "),
        "check_ok": frame.check_ok,
        "answers": report.answers,
        "latency_ms": None if report.latency_s is None else round(report.latency_s * 1000, 3),
        "anomalies": [a.value for a in report.anomalies],
    }


class _Lines:
    """One line per report: text, or JSON."""

    def __init__(self, json: bool, epoch: float) -> None:
        self._json = json
        self._epoch = epoch

    def add(self, report: SniffedFrame | Unanswered) -> None:
        row = _row(report, self._epoch)
        if self._json:
            print_json(row)
            return
        flags = f"  !! {', '.join(row['anomalies'])}" if row["anomalies"] else ""
        if row["kind"] == "unanswered":
            print(f"{_clock(row)}  #{row['request']} {row['summary']}{flags}", flush=True)
            return
        pair = f"  (answers #{row['answers']}, {row['latency_ms']} ms)" if row["answers"] else ""
        print(f"{_clock(row)}  #{row['n']} {row['role']:<8} {row['summary']}{pair}{flags}")
        sys.stdout.flush()

    def close(self) -> None:
        pass


class _LiveTable:
    """The latest frames in a rich table, the counters under it."""

    def __init__(self, sniffing: Sniffing, epoch: float) -> None:
        from rich.live import Live

        self._sniffing = sniffing
        self._epoch = epoch
        self._rows: deque[dict[str, Any]] = deque(maxlen=_ROWS)
        self._live = Live(self._render(), auto_refresh=True, refresh_per_second=8)
        self._live.start()

    def add(self, report: SniffedFrame | Unanswered) -> None:
        self._rows.append(_row(report, self._epoch))
        self._live.update(self._render())

    def _render(self) -> Any:
        from rich.console import Group
        from rich.table import Table
        from rich.text import Text

        table = Table(title=f"sniffing {self._sniffing.description}", expand=True)
        for column in ("#", "t", "what", "node", "meaning", "pair", "flags"):
            table.add_column(column, overflow="fold")
        for row in self._rows:
            flags = ", ".join(row["anomalies"])
            style = "red" if flags else None
            if row["kind"] == "unanswered":
                table.add_row(
                    "", _clock(row), "—", _node(row), row["summary"],
                    f"#{row['request']}", flags, style=style,
                )  # fmt: skip
                continue
            pair = f"#{row['answers']} {row['latency_ms']} ms" if row["answers"] else ""
            table.add_row(
                str(row["n"]), _clock(row), row["role"], _node(row), row["summary"],
                pair, flags, style=style,
            )  # fmt: skip
        stats = self._sniffing.stats
        counters = Text(
            f"bytes {stats.bytes}  paired {stats.paired}  "
            + "  ".join(f"{what} {n}" for what, n in sorted(stats.anomalies.items()))
        )
        return Group(table, counters)

    def close(self) -> None:
        self._live.stop()


def _clock(row: dict[str, Any]) -> str:
    """``14:03:07.412``, local time."""
    t = row["t"]
    return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int(t * 1000) % 1000:03d}"


def _node(row: dict[str, Any]) -> str:
    return "" if row["node"] is None else f"{row['node']:02d}"
