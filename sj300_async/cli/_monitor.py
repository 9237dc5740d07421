"""``sj300 monitor``: a live view of many drives, polled by :class:`~sj300_async.Poller`.

Without ``--url`` and without ``SJ300_URL`` it is a demo: an in-memory bus
of eight simulated drives that :mod:`._demo` keeps busy (ramping, reversing,
one tripping now and then and being reset).

Output, by where stdout goes:

- a terminal: a table refreshing in place (rich ``Live``), one row per
  drive: node, state (status A / status C), set frequency (F001), output
  frequency, current, voltage, torque, power, last error, latency, link;
- anything else: one plain line per drive per poll, for logs;
- ``--json`` (either way): one JSON object per sample per line, flushed:
  the fields of :class:`~sj300_async.Sample` (``status``, ``monitor`` as in
  ``sj300 status --json``; ``parameters`` holds ``F001``), plus ``time``,
  the wall-clock time (Unix seconds; ``timestamp`` is the event loop's).

It runs until Ctrl-C (exit 0), or ``--count`` samples, or ``--duration``
seconds. A drive that stops answering turns offline and is probed every few
seconds instead of being polled; the monitor itself never stops for a
failing drive or a dropped link.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import time
from collections.abc import AsyncIterator, Coroutine
from dataclasses import dataclass
from typing import Any, Final

from .._poller import Poller, Sample
from ..bus._bus import Bus
from ..sj300._codes import StatusA
from ..sj300._payloads import InverterStatus, MonitorData
from ._args import parse_any_nodes
from ._common import add_bus_options, add_json_option, bus_url, open_cli_bus, positive_float
from ._demo import run_demo
from ._output import Column, human, is_terminal, jsonable, print_json
from ._session import run_async

__all__ = ["add_parser"]

_log = logging.getLogger("sj300_async.cli.monitor")

#: The embedded demo's bus.
DEMO_URL: Final = "sim://?nodes=1-8"
#: The setpoint each poll reads along with status and monitor.
_SETPOINT: Final = "F001"

_COLUMNS: Final = (
    Column("node", "right"),
    Column("state"),
    Column("set Hz", "right"),
    Column("out Hz", "right"),
    Column("current A", "right"),
    Column("voltage V", "right"),
    Column("torque %", "right"),
    Column("power kW", "right"),
    Column("last error"),
    Column("latency ms", "right"),
    Column("link"),
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
        "a demo of eight simulated drives.",
    )
    p.add_argument(
        "--nodes",
        type=parse_any_nodes,
        default=list(range(1, 9)),
        metavar="LIST",
        help="drives to poll, e.g. 1-4,7 (default 1-8)",
    )
    p.add_argument(
        "--interval",
        type=positive_float,
        default=0.5,
        metavar="SECONDS",
        help="time between polls of a drive (default 0.5)",
    )
    p.add_argument("--count", type=_positive_int, metavar="N", help="stop after N samples")
    p.add_argument("--duration", type=positive_float, metavar="SECONDS", help="stop after this")
    add_json_option(p)
    add_bus_options(p, default_url=None)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Monitor until done or interrupted; return 0."""
    try:
        return run_async(_monitor(args))
    except KeyboardInterrupt:  # the normal way to stop a monitor
        return 0


async def _monitor(args: argparse.Namespace) -> int:
    url = bus_url(args)
    async with open_cli_bus(args, url or DEMO_URL, any_protocol=True) as bus:
        poller = Poller(interval_s=args.interval, parameters=(_SETPOINT,))
        poller.add(bus, args.nodes)
        # Subscribed before polling starts, so not even the first sample is missed.
        # Unbounded, but printing is synchronous: the poller cannot run ahead of it.
        samples: asyncio.Queue[Sample] = asyncio.Queue()
        poller.on_sample(samples.put_nowait)
        board = _Board(bus, args.nodes, demo=url is None)
        async with poller, _demo(bus, enabled=url is None):
            with board.live(enabled=is_terminal() and not args.json):
                await _until_terminated(_consume(args, samples, board))
    return 0


async def _until_terminated(work: Coroutine[Any, Any, None]) -> None:
    """Run *work* until it ends or SIGTERM comes (then cancel it and return normally).

    SIGINT needs nothing: asyncio.run turns it into KeyboardInterrupt after
    cleaning up, and :func:`run` makes that exit 0.
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


@contextlib.asynccontextmanager
async def _demo(bus: Bus, *, enabled: bool) -> AsyncIterator[None]:
    if not enabled:
        yield
        return
    task = asyncio.create_task(run_demo(bus), name="sj300 demo")
    try:
        yield
    finally:
        task.cancel()
        await asyncio.wait([task])
        if not task.cancelled() and task.exception() is not None:
            _log.warning("the demo stopped: %s", task.exception())


async def _consume(args: argparse.Namespace, samples: asyncio.Queue[Sample], board: _Board) -> None:
    count = 0
    with contextlib.suppress(TimeoutError):  # --duration is up
        async with asyncio.timeout(args.duration):
            while args.count is None or count < args.count:
                sample = await samples.get()
                board.update(sample)
                if args.json:
                    print_json({**jsonable(sample), "time": time.time()})
                elif not board.is_live:
                    print(board.plain_line(sample), flush=True)
                count += 1


@dataclass(slots=True)
class _LastError:
    message: str
    at: float  #: wall-clock time


class _Board:
    """The latest sample and the last error of every drive, rendered as a table or lines."""

    def __init__(self, bus: Bus, nodes: list[int], *, demo: bool) -> None:
        self._bus = bus
        self._nodes = nodes
        self._demo = demo
        self._samples: dict[int, Sample] = {}
        self._errors: dict[int, _LastError] = {}
        self.is_live = False

    def update(self, sample: Sample) -> None:
        self._samples[sample.node] = sample
        if sample.error is not None:
            self._errors[sample.node] = _LastError(sample.error, time.time())

    @contextlib.contextmanager
    def live(self, *, enabled: bool) -> Any:
        if not enabled:
            yield
            return
        from rich.live import Live

        with Live(get_renderable=self._table, refresh_per_second=4):
            self.is_live = True
            try:
                yield
            finally:
                self.is_live = False

    def _table(self) -> Any:
        from rich import box
        from rich.table import Table
        from rich.text import Text

        what = "demo: 8 simulated drives" if self._demo else self._bus.description
        table = Table(
            title=f"sj300 monitor — {what}", caption="Ctrl-C to stop", box=box.SIMPLE_HEAD
        )
        for column in _COLUMNS:
            table.add_column(
                column.header,
                justify=column.justify,
                no_wrap=True,
                max_width=40 if column.header == "last error" else None,
                min_width=26 if column.header == "state" else None,
                overflow="ellipsis",
            )
        for node in self._nodes:
            sample = self._samples.get(node)
            if sample is None:
                table.add_row(f"{node:02d}", "…", *[""] * (len(_COLUMNS) - 2))
                continue
            cells: list[Any] = self._cells(sample)
            cells[1] = Text(cells[1], style=_state_style(sample))
            cells[8] = Text(self._error_text(sample), style="red" if sample.error else "dim")
            cells[10] = Text(cells[10], style="green" if sample.online else "bold red")
            table.add_row(*cells)
        return table

    def _error_text(self, sample: Sample) -> str:
        last = self._errors.get(sample.node)
        if last is None:
            return ""
        if sample.error is not None:
            return last.message
        return f"{last.message} ({time.time() - last.at:.0f} s ago)"

    def _cells(self, sample: Sample) -> list[str]:
        m = sample.monitor
        setpoint = sample.parameters.get(_SETPOINT)
        latency = "-" if sample.latency_s is None else f"{sample.latency_s * 1000:.1f}"
        return [
            f"{sample.node:02d}",
            _state(sample),
            "-" if setpoint is None else f"{setpoint:.2f}",
            "-" if m is None else f"{m.output_frequency_hz:.2f}",
            "-" if m is None else f"{m.output_current_a:.1f}",
            "-" if m is None else f"{m.output_voltage_v:.1f}",
            "-" if not isinstance(m, MonitorData) else str(m.output_torque_percent),
            "-" if not isinstance(m, MonitorData) else f"{m.power_kw:.1f}",
            sample.error or "",
            latency,
            "online" if sample.online else "offline",
        ]

    def plain_line(self, sample: Sample) -> str:
        """One line for a log: time, node, link, state, values with units, then any error."""
        (node, state, set_hz, out_hz, amps, volts, torque, kw, error, latency, link) = self._cells(
            sample
        )
        now = time.time()
        clock = time.strftime("%H:%M:%S", time.localtime(now)) + f".{int(now % 1 * 1000):03d}"
        line = (
            f"{clock} node {node} {link:<7} {state:<30} set {set_hz:>6} Hz  out {out_hz:>6} Hz"
            f"  {amps:>6} A  {volts:>6} V  {torque:>4} %  {kw:>6} kW  {latency:>6} ms"
        )
        return f"{line}  error: {error}" if error else line


def _state(sample: Sample) -> str:
    status = sample.status
    if status is None:
        return "-"
    if isinstance(status, InverterStatus):
        return f"{human(status.a)} / {human(status.c)}"
    # An FR-700 reports bits, not states.
    if status.tripped:
        return "trip"
    if status.running:
        return "run reverse" if status.reverse else "run forward"
    return "stop"


def _state_style(sample: Sample) -> str:
    status = sample.status
    if status is None:
        return "dim"
    if status.tripped:
        return "bold red"
    running = status.a == StatusA.RUNNING if isinstance(status, InverterStatus) else status.running
    return "green" if running else ""
