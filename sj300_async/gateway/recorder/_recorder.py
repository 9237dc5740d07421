"""The trip recorder: sees each new trip in the gateway's samples, keeps its record.

The gateway hands it every snapshot it builds (:meth:`TripRecorder.observe`:
a comparison or two, nothing kept per sample) and its lines as they come and
go. A trip opens a pending record; ``after_s`` later the record is taken
from what the gateway already keeps (the drive's trend, the line's
traffic, the audit log), turned into JSON and pcapng in a thread and kept
in the store (:mod:`._store`). Then the doors are told (``recorded``).

Decisions:

- **A new trip** is the status going from not tripped to tripped (the
  poll saw it), or the trip history's count going up with no such change
  since the history was read before (the trip came and was reset between
  two polls: the history saw it). The first status and the first history
  read of a drive are where it starts from, not trips: a gateway started
  beside a drive that tripped last week makes no record of it.
- **Its instant** is the status read that showed it (the history read's,
  for one the history saw), and **its code and meaning** the trip history's
  newest record read after it (the snapshot's present trip). A drive whose
  history is not read by then (``trips_interval_s = 0``) has a record
  without them.
- **Copied on the loop, encoded off it.** Taking the window is copying:
  the trend's columns (decoded, about 1 ms for 1,000 samples), the line
  log's chunks in the window, a few audit lines. The pcapng and the JSON
  are made in a thread.
- **Bounded.** At most :data:`MAX_PENDING` records wait at once (a whole
  plant tripping on a mains dip); past it a trip is counted and logged,
  not recorded.
- A line removed by a reload, and the gateway stopping, take their
  pending records at once (a shorter ``after``), and a stop waits for
  them to be written: a record survives the restart that follows it.
"""

from __future__ import annotations

import asyncio
import functools
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

from ...bus import Kept
from ...profiles import DriveSnapshot, Trip
from .._line_traffic import LEAD_S, LineTraffic
from .._trend_columns import served_columns
from ._record import new_record, record_id
from ._settings import RecorderConfig
from ._store import RecordSummary, TripStore

if TYPE_CHECKING:
    from .._audit import AuditLog
    from .._drive import GatewayDrive
    from .._gateway import GatewayLine

__all__ = ["MAX_PENDING", "TripRecorder"]

_log = logging.getLogger("sj300_async.gateway.recorder")

#: Records waiting for their ``after_s`` or their write, at most.
MAX_PENDING: Final = 4096
#: Seconds a stop waits for the records being written.
CLOSE_S: Final = 10.0


@dataclass(slots=True)
class _Watch:
    """What the recorder last saw of one drive."""

    tripped: bool | None = None
    #: The trip history's count at its last read (None: not read yet).
    count: int | None = None
    #: A trip the poll saw since the history's last read (the history's next count
    #: includes it: not a second trip).
    unmatched: int = 0


@dataclass(slots=True)
class _Pending:
    """A trip whose record waits for its ``after_s``."""

    drive: GatewayDrive
    #: The trip's instant, on the loop's clock and in Unix time.
    at: float
    unix: float
    seen_by: str
    trip: Trip | None = None
    timer: asyncio.TimerHandle | None = field(default=None, repr=False)


class TripRecorder:
    """Every trip's record (see the module docstring)."""

    def __init__(
        self,
        config: RecorderConfig,
        audit: AuditLog,
        gateway_id: str,
        recorded: Callable[[RecordSummary, GatewayDrive], None],
    ) -> None:
        self.config = config
        self.store = TripStore(config)
        self._audit = audit
        self._gateway_id = gateway_id
        self._recorded = recorded
        self._watch: dict[tuple[str, int], _Watch] = {}
        #: Each line's traffic, by name, with the line it is of.
        self._traffic: dict[str, tuple[GatewayLine, LineTraffic]] = {}
        self._pending: dict[tuple[str, int], _Pending] = {}
        self._writing: set[asyncio.Task[None]] = set()
        #: Trips seen, by what saw them; records dropped (too many pending).
        self.counts: dict[str, int] = {"poll": 0, "trip history": 0, "dropped": 0}
        #: Told of each record kept, after the doors (``sj300 trips --record`` prints it).
        self.listeners: list[Callable[[RecordSummary], None]] = []

    async def start(self) -> None:
        """Read the records kept before (a directory's)."""
        await self.store.load()

    # -- the gateway's lines and samples ----------------------------------------------------

    def add_line(self, line: GatewayLine) -> None:
        """Watch *line* from now: its traffic kept for the records' frames."""
        name = line.config.name
        if name in self._traffic:  # a reload replaces the line: the old one's records first
            self._retire(name)
        keep_s = self.config.before_s + self.config.after_s + 2 * LEAD_S
        self._traffic[name] = (line, LineTraffic(name, line.bus, keep_s))

    def remove_line(self, line: GatewayLine) -> None:
        """*line* goes (a reload): its pending records are taken now, its traffic let go
        (already, when the line that replaces it came first)."""
        entry = self._traffic.get(line.config.name)
        if entry is not None and entry[0] is line:
            self._retire(line.config.name)

    def _retire(self, name: str) -> None:
        for key in [key for key in self._pending if key[0] == name]:
            self._take(self._pending[key])
        for key in [key for key in self._watch if key[0] == name]:
            del self._watch[key]
        _, traffic = self._traffic.pop(name)
        traffic.close()

    def observe(self, drive: GatewayDrive, snapshot: DriveSnapshot) -> None:
        """*drive*'s new *snapshot* (a sample's, a write's, a history read's)."""
        watch = self._watch.get(drive.key)
        if watch is None:
            watch = self._watch[drive.key] = _Watch()
        tripped = snapshot.tripped
        if tripped is not None and tripped != watch.tripped:
            was, watch.tripped = watch.tripped, tripped
            if tripped and was is False:
                watch.unmatched += 1
                self._open(drive, snapshot, snapshot.status_at, "poll")
        trips = snapshot.trips
        if trips is not None and trips.total_count is not None:
            count = trips.total_count
            if watch.count is not None and count > watch.count:
                if watch.unmatched:
                    watch.unmatched = 0
                else:
                    self._open(drive, snapshot, snapshot.trips_at, "trip history")
            elif watch.count is None:
                watch.unmatched = 0
            watch.count = count
        pending = self._pending.get(drive.key)
        if pending is not None and snapshot.trip is not None and pending.trip is None:
            pending.trip = snapshot.trip  # the history read after the trip names it

    def _open(self, drive: GatewayDrive, snapshot: DriveSnapshot, at: float, seen_by: str) -> None:
        self.counts[seen_by] += 1
        if drive.key in self._pending:  # a second trip inside the first one's after_s
            self._take(self._pending[drive.key])
        if len(self._pending) + len(self._writing) >= MAX_PENDING:
            self.counts["dropped"] += 1
            _log.warning("line %s node %d: a trip not recorded: %d records are pending",
                         *drive.key, MAX_PENDING)  # fmt: skip
            return
        unix = snapshot.time - (snapshot.taken_at - at)
        trip = None
        if seen_by == "trip history" and snapshot.trips is not None and snapshot.trips.records:
            trip = snapshot.trips.records[0]
        pending = _Pending(drive, at, unix, seen_by, trip)
        self._pending[drive.key] = pending
        loop = asyncio.get_running_loop()
        pending.timer = loop.call_at(at + self.config.after_s, self._take, pending)
        _log.info("line %s node %d: tripped (seen by the %s); its record in %g s",
                  *drive.key, seen_by, self.config.after_s)  # fmt: skip

    # -- making a record --------------------------------------------------------------------

    def _take(self, pending: _Pending) -> None:
        """The window of *pending*, copied now; written in a task."""
        if pending.timer is not None:
            pending.timer.cancel()
        if self._pending.get(pending.drive.key) is pending:
            del self._pending[pending.drive.key]
        drive, line, config = pending.drive, pending.drive.line, self.config
        if pending.trip is None:
            pending.trip = drive.snapshot.trip
        begin, end = pending.unix - config.before_s, pending.unix + config.after_s
        if drive.trend is not None:
            # Every sample from before_s before to after_s after (since excludes its time).
            columns = drive.trend.columns(begin - 0.001, until=end)
        else:
            columns = {"time": []}
        writes = [
            entry
            for entry in self._audit.recent
            if entry["line"] == line.name
            and entry["node"] == drive.node
            and begin <= float(entry["time"]) <= end  # type: ignore[arg-type]
        ]
        name = record_id(pending.unix, line.name, drive.node)
        record = new_record(
            record=name,
            gateway=self._gateway_id,
            line=line.name,
            node=drive.node,
            unit=drive.unit,
            protocol=line.protocol,
            unix=pending.unix,
            seen_by=pending.seen_by,
            interval_s=line.interval_s,
            before_s=config.before_s,
            after_s=config.after_s,
            trip=pending.trip,
            samples=served_columns(columns),
            writes=writes,
        )
        entry = self._traffic.get(line.name)
        traffic = None if entry is None else entry[1]
        start, stop = pending.at - config.before_s, pending.at + config.after_s
        chunks = [] if traffic is None else traffic.span(start - LEAD_S, stop)
        task = asyncio.create_task(
            self._write(record, traffic, chunks, start, stop, drive),
            name=f"sj300-trip-record-{name}",
        )
        self._writing.add(task)
        task.add_done_callback(self._writing.discard)

    async def _write(
        self,
        record: dict[str, Any],
        traffic: LineTraffic | None,
        chunks: list[Kept],
        start: float,
        stop: float,
        drive: GatewayDrive,
    ) -> None:
        try:
            frames = b""
            if traffic is not None:
                frames = await asyncio.to_thread(traffic.pcapng_of, chunks, start, stop)
            summary = await self.store.add(record, frames)
        except Exception:  # a bug of ours: this record is lost, the gateway goes on
            _log.exception("trip record %s could not be made", record["id"])
            return
        if summary is None:
            return
        _log.info("trip record %s kept (%d bytes)", summary.id, summary.size)
        tells = [functools.partial(self._recorded, summary, drive)]
        tells += [functools.partial(listener, summary) for listener in self.listeners]
        for tell in tells:
            try:
                tell()
            except Exception:  # a door's failure to announce it: the record is kept
                _log.exception("trip record %s: announcing it failed", summary.id)

    async def close(self) -> None:
        """Take every pending record now, and wait (bounded) for them to be written."""
        for pending in list(self._pending.values()):
            self._take(pending)
        if self._writing:
            _, left = await asyncio.wait(set(self._writing), timeout=CLOSE_S)
            if left:
                _log.error("%d trip record(s) not written within %g s of the stop",
                           len(left), CLOSE_S)  # fmt: skip
                for task in left:
                    task.cancel()
                await asyncio.gather(*left, return_exceptions=True)  # ended, not left behind
        for _, traffic in self._traffic.values():
            traffic.close()
        self._traffic.clear()

    @property
    def pending(self) -> int:
        """Records waiting for their ``after_s`` or their write."""
        return len(self._pending) + len(self._writing)
