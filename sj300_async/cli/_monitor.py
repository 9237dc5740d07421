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
  the fields of :class:`~sj300_async.Sample` (``status``, ``monitor`` as in
  ``sj300 status --json``; ``parameters`` holds ``F001``), plus ``time``,
  the wall-clock time (Unix seconds; ``timestamp`` is the event loop's).

Each sample becomes a :class:`~sj300_async.profiles.DriveSnapshot` built by
the drive's profile, and the rows show the snapshot: states read as a person
would (``stopped``, ``accelerating``, ``running``, ``tripped``), the set
frequency where the profile names a parameter for it (SJ300 F001), torque
and power where the protocol measures them. A tripped drive's row names its
trip (``tripped E07 over-voltage``; an FR-700 ``tripped fault H10``), read
once per trip from the drive's history by its profile. A drive that has never
answered is ``offline`` (:attr:`~sj300_async.Sample.answered`); one that
stops answering turns offline and is probed every few seconds instead of
being polled; the monitor itself never stops for a failing drive or a
dropped link.

With ``--url mqtt://HOST:PORT[/prefix]`` (or ``mqtts://``) it opens no bus
and shows the fleet instead: every drive of every gateway on the broker
(:mod:`._fleet`).

It runs until Ctrl-C (exit 130, as for any command), SIGTERM (exit 0),
``--count`` cycles (a cycle is one sample of every node; a node set aside
as offline between its probes is not waited for) or ``--duration``
seconds.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
import time
from collections.abc import AsyncIterator, Coroutine
from dataclasses import dataclass
from typing import Any, Final

from .. import Poller, Sample
from ..bus import Bus, parse_bus_url
from ..profiles import DriveReadings, DriveSnapshot, Profile, Trip, build_snapshot
from ..wire import SJ300Error
from ._args import format_nodes, parse_any_nodes
from ._common import (
    add_bus_options,
    add_json_option,
    bus_url,
    open_cli_bus,
    positive_float,
    profile_of,
)
from ._demo import run_demo
from ._errors import FAILURE, CliError
from ._output import Justify, is_terminal, jsonable, print_json
from ._progress import progress
from ._scan import probe
from ._session import run_async
from ._tripinfo import trip_or_none

__all__ = ["add_parser"]

_log = logging.getLogger("sj300_async.cli.monitor")

#: The embedded demo's bus.
DEMO_URL: Final = "sim://?nodes=1-8"
#: The nodes polled on a ``sim://`` bus whose simulated drives are not known.
_DEFAULT_NODES: Final = tuple(range(1, 9))
#: Exit status of Ctrl-C (SIGINT), as for every command.
INTERRUPTED: Final = 130
#: Below this many terminal columns the table takes its compact layout.
COMPACT_BELOW: Final = 100


@dataclass(frozen=True, slots=True)
class _Field:
    """A column of the live table: its header, how it lines up, the cell it shows."""

    header: str
    key: str  #: the cell's key in :meth:`_Board.cells`
    justify: Justify = "right"
    #: Takes the room the others leave, cut with … when short (never a number column).
    flexible: bool = False
    #: A flexible column's least width (and, for ``max_width``, its most).
    min_width: int = 0
    max_width: int | None = None


_NODE = _Field("node", "node")
_STATE = _Field("state", "state", "left", flexible=True, min_width=12)
_SET_HZ = _Field("set Hz", "set_hz")
_OUT_HZ = _Field("out Hz", "out_hz")
_LINK = _Field("link", "link", "left")
_ERROR = _Field("last error", "error", "left", flexible=True, min_width=10, max_width=40)

#: The table's layouts, richest first: the first that fits the terminal is used
#: (from :data:`COMPACT_BELOW` columns on; below, always the compact one).
_LAYOUTS: Final = (
    (
        _NODE,
        _STATE,
        _SET_HZ,
        _OUT_HZ,
        _Field("current A", "amps"),
        _Field("voltage V", "volts"),
        _Field("torque %", "torque"),
        _Field("power kW", "kw"),
        _ERROR,
        _Field("latency ms", "latency"),
        _LINK,
    ),
    (
        _NODE,
        _STATE,
        _SET_HZ,
        _OUT_HZ,
        _Field("current A", "amps"),
        _Field("voltage V", "volts"),
        _ERROR,
        _LINK,
    ),
)
_COMPACT: Final = (
    _NODE,
    _Field("state", "state", "left", flexible=True, min_width=7),
    _SET_HZ,
    _OUT_HZ,
    _Field("A", "amps"),
    _Field("V", "volts"),
    _LINK,
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
        help="stop after N cycles (a cycle: one sample of every node; mqtt://: N states)",
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
        # Unbounded, but printing is synchronous: the poller cannot run ahead of it.
        samples: asyncio.Queue[Sample] = asyncio.Queue()
        poller.on_sample(samples.put_nowait)
        board = _Board(bus, profile, nodes, demo=url is None)
        async with poller, _demo(bus, enabled=url is None):
            try:
                with board.live(enabled=is_terminal() and not args.json):
                    await _until_terminated(_consume(args, poller, bus, samples, board))
            finally:
                board.trips.close()
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


async def _consume(
    args: argparse.Namespace,
    poller: Poller,
    bus: Bus,
    samples: asyncio.Queue[Sample],
    board: _Board,
) -> None:
    cycles = 0
    pending = set(board.nodes)  # the nodes not sampled yet this cycle
    with contextlib.suppress(TimeoutError):  # --duration is up
        async with asyncio.timeout(args.duration):
            while args.count is None or cycles < args.count:
                sample = await samples.get()
                board.update(sample)
                if args.json:
                    print_json({**jsonable(sample), "time": time.time()})
                elif not board.is_live:
                    print(board.plain_line(sample), flush=True)
                pending.discard(sample.node)
                # A node the poller has set aside as offline is probed only now and then:
                # the cycle does not wait for it.
                if not any(poller.health(bus, node).online for node in pending):
                    cycles += 1
                    pending = set(board.nodes)


class _TripNames:
    """The trip each tripped drive is in, read once per trip from its history.

    The status says only that a drive is tripped; the profile reads which
    trip, in a task of its own (the poll goes on meanwhile). A read that
    fails is tried again at the next tripped sample.
    """

    def __init__(self, bus: Bus, profile: Profile) -> None:
        self._bus = bus
        self._profile = profile
        self._known: dict[int, Trip | None] = {}
        self._reading: dict[int, asyncio.Task[None]] = {}

    def update(self, snapshot: DriveSnapshot) -> None:
        node = snapshot.node
        if snapshot.tripped is None:  # no status this poll: nothing learnt
            return
        if not snapshot.tripped:
            self._known.pop(node, None)
            task = self._reading.pop(node, None)
            if task is not None:
                task.cancel()
            return
        if node not in self._known and node not in self._reading:
            self._reading[node] = asyncio.create_task(self._read(node))

    def get(self, node: int) -> Trip | None:
        """The trip *node* is in, if known."""
        return self._known.get(node)

    async def _read(self, node: int) -> None:
        try:
            self._known[node] = await trip_or_none(self._profile, self._bus.drive(node))
        except SJ300Error as exc:
            _log.debug("node %02d: trip history not read: %s", node, exc)
        finally:
            self._reading.pop(node, None)

    def close(self) -> None:
        """Cancel the reads still under way."""
        for task in self._reading.values():
            task.cancel()
        self._reading.clear()


@dataclass(slots=True)
class _LastError:
    message: str
    at: float  #: wall-clock time


class _Board:
    """The latest sample and the last error of every drive, rendered as a table or lines."""

    def __init__(self, bus: Bus, profile: Profile, nodes: list[int], *, demo: bool) -> None:
        self._bus = bus
        self._profile = profile
        self.nodes = nodes
        self._demo = demo
        self._samples: dict[int, Sample] = {}
        self._snapshots: dict[int, DriveSnapshot] = {}
        self._errors: dict[int, _LastError] = {}
        self.trips = _TripNames(bus, profile)
        self.is_live = False
        self._console: Any = None

    def update(self, sample: Sample) -> None:
        self._samples[sample.node] = sample
        snapshot = self.snapshot(sample)
        self._snapshots[sample.node] = snapshot
        self.trips.update(snapshot)
        if sample.error is not None:
            self._errors[sample.node] = _LastError(sample.error, time.time())

    @contextlib.contextmanager
    def live(self, *, enabled: bool) -> Any:
        if not enabled:
            yield
            return
        from rich.console import Console
        from rich.live import Live

        self._console = Console()
        with Live(get_renderable=self.table, console=self._console, refresh_per_second=4):
            self.is_live = True
            try:
                yield
            finally:
                self.is_live = False

    def table(self, width: int | None = None) -> Any:
        """The rich table of every drive, laid out for *width* columns (default: the console's)."""
        from rich import box
        from rich.table import Table
        from rich.text import Text

        if width is None:
            width = self._console.width if self._console is not None else 160
        rows = [self._row(node) for node in self.nodes]
        fields, widths = _layout(width, rows)
        what = "demo: 8 simulated drives" if self._demo else self._bus.description
        table = Table(
            title=f"sj300 monitor — {what}", caption="Ctrl-C to stop", box=box.SIMPLE_HEAD
        )
        for field in fields:
            table.add_column(
                field.header,
                justify=field.justify,
                no_wrap=True,
                min_width=widths[field.key],
                max_width=widths[field.key],
                overflow="ellipsis",
            )
        for node, cells in zip(self.nodes, rows, strict=True):
            sample = self._samples.get(node)
            styled: dict[str, Any] = dict(cells)
            if sample is not None:
                styled["state"] = Text(cells["state"], style=self._state_style(node))
                styled["error"] = Text(cells["error"], style="red" if sample.error else "dim")
                styled["link"] = Text(cells["link"], style="green" if _up(sample) else "bold red")
            table.add_row(*(styled[field.key] for field in fields))
        return table

    def _row(self, node: int) -> dict[str, str]:
        sample = self._samples.get(node)
        if sample is None:
            return dict.fromkeys(_KEYS, "") | {"node": f"{node:02d}", "state": "…"}
        return self.cells(sample) | {"error": self._error_text(sample)}

    def _error_text(self, sample: Sample) -> str:
        last = self._errors.get(sample.node)
        if last is None:
            return ""
        if sample.error is not None:
            return last.message
        return f"{last.message} ({time.time() - last.at:.0f} s ago)"

    def snapshot(self, sample: Sample) -> DriveSnapshot:
        """*sample* alone as the profile sees it (a value not read this poll is unknown)."""
        readings = DriveReadings()
        readings.take(sample, self._profile)
        return build_snapshot(
            self._profile,
            readings,
            line=self._bus.description,
            node=sample.node,
            unit=None,
            now=sample.timestamp,
            wall=time.time(),
        )

    def cells(self, sample: Sample) -> dict[str, str]:
        """Every cell of *sample*'s row as text, keyed as :class:`_Field` names them."""
        s = self._snapshots.get(sample.node)
        if s is None or s.taken_at != sample.timestamp:
            s = self.snapshot(sample)
        latency = "-" if sample.latency_s is None else f"{sample.latency_s * 1000:.1f}"
        return {
            "node": f"{sample.node:02d}",
            "state": self._state(s),
            "set_hz": _number(s.set_frequency_hz, 2),
            "out_hz": _number(s.output_frequency_hz, 2),
            "amps": _number(s.output_current_a, 1),
            "volts": _number(s.output_voltage_v, 1),
            "torque": _number(s.output_torque_percent, 0),
            "kw": _number(s.power_kw, 1),
            "error": sample.error or "",
            "latency": latency,
            "link": "online" if _up(sample) else "offline",
        }

    def _state(self, snapshot: DriveSnapshot) -> str:
        if snapshot.state is None:
            return "-"
        if snapshot.tripped:
            trip = self.trips.get(snapshot.node)
            if trip is not None:
                return f"{snapshot.state} {trip}"
        return snapshot.state

    def _state_style(self, node: int) -> str:
        snapshot = self._snapshots.get(node)
        if snapshot is None or snapshot.tripped is None:
            return "dim"
        if snapshot.tripped:
            return "bold red"
        return "green" if snapshot.running else ""

    def plain_line(self, sample: Sample) -> str:
        """One line for a log: time, node, link, state, values with units, then any error."""
        c = self.cells(sample)
        now = time.time()
        clock = time.strftime("%H:%M:%S", time.localtime(now)) + f".{int(now % 1 * 1000):03d}"
        line = (
            f"{clock} node {c['node']} {c['link']:<7} {c['state']:<24}"
            f" set {c['set_hz']:>6} Hz  out {c['out_hz']:>6} Hz  {c['amps']:>6} A"
            f"  {c['volts']:>6} V  {c['torque']:>4} %  {c['kw']:>6} kW  {c['latency']:>6} ms"
        )
        return f"{line}  error: {c['error']}" if c["error"] else line


_KEYS: Final = frozenset(f.key for layout in (*_LAYOUTS, _COMPACT) for f in layout)


def _layout(width: int, rows: list[dict[str, str]]) -> tuple[tuple[_Field, ...], dict[str, int]]:
    """The layout for *width* columns and each of its columns' width.

    A fixed column is as wide as its widest cell or header; the flexible ones
    (state, last error) share the rest, each at least its ``min_width``.
    """
    from rich.cells import cell_len

    def natural(field: _Field) -> int:
        return max([cell_len(field.header), *(cell_len(row[field.key]) for row in rows)])

    candidates = (_COMPACT,) if width < COMPACT_BELOW else (*_LAYOUTS, _COMPACT)
    for fields in candidates:
        # Per column: one space of padding each side and a divider; the edges: 1 more.
        room = width - (3 * len(fields) + 1)
        fixed = {f.key: natural(f) for f in fields if not f.flexible}
        flexible = [f for f in fields if f.flexible]
        left = room - sum(fixed.values())
        if left >= sum(f.min_width for f in flexible) or fields is _COMPACT:
            break
    widths = dict(fixed)
    for i, field in enumerate(flexible):
        later = sum(f.min_width for f in flexible[i + 1 :])
        want = min(natural(field), field.max_width or natural(field))
        widths[field.key] = max(1, min(want, left - later))
        left -= widths[field.key]
    return fields, widths


def _number(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _up(sample: Sample) -> bool:
    """Online and heard from: a drive that has never answered is offline."""
    return sample.online and sample.answered
