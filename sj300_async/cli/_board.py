"""The bus monitor's board: every drive's latest snapshot, shown as a live table or log lines.

Each sample becomes a :class:`~sj300_async.profiles.DriveSnapshot` built by
the drive's profile from that sample alone (a value not read this poll is
unknown, ``-``), and the rows show the snapshot; a tripped drive's trip is
read once per trip from its history (:class:`_TripNames`), and the set
frequency of a protocol that holds it in no parameter the poll reads
(FR-700) every :data:`SETPOINT_EVERY_S` (:class:`_SetFrequencies`), each
beside the poll. Lines and JSON records wait for those reads
(:meth:`Board.settle`), so even ``--count 1`` names a drive's trip and
shows its set frequency; the live table shows them when they come. The table's
columns fit the terminal (:mod:`._fit`): from :data:`COMPACT_BELOW` columns
the richest layout that fits, below it a compact one. The columns keep
their width over a run, in the table and in the plain lines: the state's
is :data:`~._fit.STATE_WIDTH` (a longer trip is cut with ``…``), the
numbers' what their values take, the link's ``offline``'s.

``--json`` prints each sample as a :class:`~._record.DriveRecord`
(:meth:`Board.record`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Coroutine
from dataclasses import dataclass
from typing import Any, Final

from .. import Sample
from ..bus import Bus, retries_at_most
from ..profiles import DriveReadings, DriveSnapshot, Profile, Trip, build_snapshot
from ..wire import SJ300Error
from ._fit import STATE_WIDTH, FitColumn, clip, fit
from ._record import DriveRecord, direction_word
from ._tripinfo import trip_or_none

__all__ = ["COMPACT_BELOW", "Board"]

_log = logging.getLogger("sj300_async.cli.monitor")

#: Below this many terminal columns the table takes its compact layout.
COMPACT_BELOW: Final = 100
#: Seconds between two reads of a drive's set frequency beside the poll (as the
#: gateway's default ``setpoint_interval_s``).
SETPOINT_EVERY_S: Final = 2.0
#: Seconds before a failed set-frequency read is tried again.
SETPOINT_AFTER_FAILURE_S: Final = 30.0

#: How wide the last error column would be, given the room.
_ERROR_WIDTH: Final = 40

_Field = FitColumn
_NODE = _Field("node", "node")
_STATE = _Field("state", "state", "left", flexible=True, min_width=12, width=STATE_WIDTH)
# A frequency up to 400.00 Hz, a current or a voltage up to 999.9 A or V.
_SET_HZ = _Field("set Hz", "set_hz", width=6)
_OUT_HZ = _Field("out Hz", "out_hz", width=6)
_LINK = _Field("link", "link", "left", width=len("offline"))
_ERROR = _Field("last error", "error", "left", flexible=True, min_width=10, width=_ERROR_WIDTH)

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
    _Field("state", "state", "left", flexible=True, min_width=7, width=STATE_WIDTH),
    _SET_HZ,
    _OUT_HZ,
    _Field("A", "amps", width=5),
    _Field("V", "volts", width=5),
    _LINK,
)


class _ReadsBeside:
    """Reads beside the poll, one task per drive at a time, cancelled at close.

    Each makes one attempt, as the poller's reads do (the bus's retries would
    let a drive that refuses one read take the line from the polls, and the
    printed lines wait for these reads).
    """

    def __init__(self, bus: Bus, profile: Profile) -> None:
        self._bus = bus
        self._profile = profile
        self._reading: dict[int, asyncio.Task[None]] = {}

    def _start(self, node: int, read: Coroutine[Any, Any, None]) -> None:
        self._reading[node] = asyncio.create_task(_one_attempt(read))

    def under_way(self, node: int) -> asyncio.Task[None] | None:
        """*node*'s read, while it goes on."""
        return self._reading.get(node)

    def close(self) -> None:
        """Cancel the reads still under way."""
        for task in self._reading.values():
            task.cancel()
        self._reading.clear()


async def _one_attempt(read: Coroutine[Any, Any, None]) -> None:
    with retries_at_most(0):
        await read


class _TripNames(_ReadsBeside):
    """The trip each tripped drive is in, read once per trip from its history.

    The status says only that a drive is tripped; the profile reads which
    trip, in a task of its own (the poll goes on meanwhile). A read that
    fails is tried again at the next tripped sample.
    """

    def __init__(self, bus: Bus, profile: Profile) -> None:
        super().__init__(bus, profile)
        self._known: dict[int, Trip | None] = {}

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
            self._start(node, self._read(node))

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


class _SetFrequencies(_ReadsBeside):
    """The set frequency of each drive whose profile names no parameter holding it.

    The poll reads a protocol's setpoint parameter (SJ300 F001) with the
    rest; FR-700 has none, so its set frequency (H6D) is read beside the
    poll in a task of its own, every :data:`SETPOINT_EVERY_S` per drive that
    answers. A read that fails leaves the value unknown (not an old one) and
    is tried again after :data:`SETPOINT_AFTER_FAILURE_S`: a drive that
    refuses it costs the line little.
    """

    def __init__(self, bus: Bus, profile: Profile) -> None:
        super().__init__(bus, profile)
        self.enabled = profile.setpoint_parameter is None
        self._known: dict[int, tuple[float | None, float]] = {}  # node -> (Hz, loop time)

    def update(self, sample: Sample) -> None:
        node = sample.node
        if not self.enabled or not sample.online or node in self._reading:
            return
        known = self._known.get(node)
        if known is None:
            self._start(node, self._read(node))
            return
        every = SETPOINT_EVERY_S if known[0] is not None else SETPOINT_AFTER_FAILURE_S
        if sample.timestamp - known[1] >= every:
            self._start(node, self._read(node))

    def get(self, node: int) -> tuple[float, float] | None:
        """*node*'s set frequency and the loop time it was read, if known."""
        known = self._known.get(node)
        return None if known is None or known[0] is None else (known[0], known[1])

    async def _read(self, node: int) -> None:
        loop = asyncio.get_running_loop()
        try:
            hz = await self._profile.read_set_frequency(self._bus.drive(node))
            self._known[node] = (hz, loop.time())
        except SJ300Error as exc:
            self._known[node] = (None, loop.time())
            _log.debug("node %02d: set frequency not read: %s", node, exc)
        finally:
            self._reading.pop(node, None)


@dataclass(slots=True)
class _LastError:
    message: str
    at: float  #: wall-clock time


class Board:
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
        self.setpoints = _SetFrequencies(bus, profile)
        self.is_live = False
        self._console: Any = None

    def update(self, sample: Sample) -> None:
        self._samples[sample.node] = sample
        snapshot = self.snapshot(sample)
        self._snapshots[sample.node] = snapshot
        self.trips.update(snapshot)
        self.setpoints.update(sample)
        if sample.error is not None:
            self._errors[sample.node] = _LastError(sample.error, time.time())

    async def settle(self, node: int) -> None:
        """Wait for *node*'s reads beside the poll under way (its trip, its set frequency)."""
        reads = [t for t in (self.trips.under_way(node), self.setpoints.under_way(node)) if t]
        if reads:
            await asyncio.wait(reads)
        if reads:  # built again with what they read
            self._snapshots[node] = self.snapshot(self._samples[node])

    def close(self) -> None:
        """Cancel the reads beside the poll still under way."""
        self.trips.close()
        self.setpoints.close()

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
        setpoint = self.setpoints.get(sample.node)
        if setpoint is not None:
            readings.set_frequency(*setpoint)
        return build_snapshot(
            self._profile,
            readings,
            line=self._bus.description,
            node=sample.node,
            unit=None,
            now=sample.timestamp,
            wall=_wall_time(sample.timestamp),
        )

    def record(self, sample: Sample) -> DriveRecord:
        """*sample* as ``--json`` prints it (the trip named once its history is read)."""
        s = self._snapshots.get(sample.node)
        if s is None or s.taken_at != sample.timestamp:
            s = self.snapshot(sample)
        trip = self.trips.get(sample.node) if s.tripped else None
        parameters: dict[str, float | None] = {
            code: reading.value for code, reading in s.parameters.items()
        }
        parameters.update(dict.fromkeys(sorted(s.unavailable_parameters)))
        return DriveRecord(
            time=s.time,
            gateway=None,
            line=s.line,
            node=s.node,
            protocol=s.protocol,
            online=_up(sample),
            state=s.state,
            running=s.running,
            tripped=s.tripped,
            trip=None if trip is None else trip.code,
            trip_meaning=None if trip is None else trip.meaning,
            direction=direction_word(s.direction),
            output_frequency_hz=s.output_frequency_hz,
            set_frequency_hz=s.set_frequency_hz,
            output_current_a=s.output_current_a,
            output_voltage_v=s.output_voltage_v,
            output_torque_percent=s.output_torque_percent,
            power_kw=s.power_kw,
            status=s.status_fields,
            parameters=parameters,
            error=sample.error,
            latency_s=sample.latency_s,
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
            f"{clock} {self._profile.node_noun} {c['node']} {c['link']:<7}"
            f" {clip(c['state'], STATE_WIDTH):<{STATE_WIDTH}}"
            f" set {c['set_hz']:>6} Hz  out {c['out_hz']:>6} Hz  {c['amps']:>6} A"
            f"  {c['volts']:>6} V  {c['torque']:>4} %  {c['kw']:>6} kW  {c['latency']:>6} ms"
        )
        return f"{line}  error: {c['error']}" if c["error"] else line


_KEYS: Final = frozenset(f.key for layout in (*_LAYOUTS, _COMPACT) for f in layout)


def _layout(width: int, rows: list[dict[str, str]]) -> tuple[tuple[FitColumn, ...], dict[str, int]]:
    """The layout for *width* columns (below :data:`COMPACT_BELOW`, the compact one) and widths."""
    candidates = (_COMPACT,) if width < COMPACT_BELOW else (*_LAYOUTS, _COMPACT)
    return fit(candidates, width, rows)


def _wall_time(loop_time: float) -> float:
    """The Unix time of the event loop's *loop_time* (a sample's time, not the time now)."""
    try:
        now = asyncio.get_running_loop().time()
    except RuntimeError:  # no loop: taken as now
        now = loop_time
    return time.time() - (now - loop_time)


def _number(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _up(sample: Sample) -> bool:
    """Online and heard from: a drive that has never answered is offline."""
    return sample.online and sample.answered
