"""The gateway process: open the lines, poll them, serve them through the northbounds, stop cleanly.

:class:`Gateway` is an async context manager. Entering it opens every line
(one :class:`~sj300_async.Bus` each, the only master on its wire), starts
the configured northbounds (:mod:`._northbound`: Modbus TCP, /metrics and
/healthz, MQTT, or any registered one), then a
:class:`~sj300_async.Poller` per line with the line's poll plan. Each
sample goes into the drive's readings, a new
:class:`~sj300_async.profiles.DriveSnapshot` is built from them, and every
northbound gets it; so does every write's read-back. Nothing is written to
a drive on start-up: the poller only reads, and writes come only from
clients, through :meth:`Gateway.write`.

Leaving it (SIGTERM in ``sj300 gateway``) stops in this order: the
northbounds, last started first (no client write starts any more; MQTT
says "offline"), the leases still held (their lapse action runs and is
waited for: the one case a command is sent on the way out), the
trip-history readers and the pollers, the lines, the audit log.

A northbound's failure stays its own: an exception from its ``publish`` is
logged (the first with its traceback, the next at DEBUG) and counted
(``sj300_gateway_publish_errors_total``), and the other northbounds, the
poller, the write that changed the drive and the trip reader go on.

What is read beside the poll (trip histories, set frequencies) is
:mod:`._beside`'s. :meth:`Gateway.reload` takes a new configuration while
it runs (:mod:`._reload` decides what changes, :mod:`._reloader` changes it).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any

from .. import Poller, Sample
from ..bus import Bus, CaptureFile, open_bus
from ..profiles import DriveSnapshot, Profile, get_profile
from ..wire import LocalProtocolError
from . import _logflood as logflood
from ._audit import AuditLog
from ._batch import SnapshotBatch
from ._beside import read_beside_the_poll
from ._check import check_recorder
from ._control import Controller
from ._drive import GatewayDrive, Lease
from ._errors import GatewayStartError
from ._gateway_metrics import all_metrics
from ._heap import collector_paused, freeze_long_lived, thaw, young_collections_raised
from ._line_health import LineHealth, UtilisationMeter, line_health
from ._line_traffic import LineTraffic
from ._logflood import FloodLimit
from ._looplag import LoopMonitor
from ._metrics import LineView, line_problems
from ._model import GatewayConfig, LineConfig
from ._northbound import Northbound, get_northbound
from ._reloader import ReloadOutcome, apply_reload, reload_file
from ._served import ServedDrive
from ._trend import Trend, trend_capacity
from ._trend_columns import columns_of, sample_of
from ._writes import Refusal, WriteRequest, WriteResult
from .recorder._recorder import TripRecorder
from .recorder._store import RecordSummary, TripStore

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["Gateway", "GatewayLine"]

_log = logging.getLogger("sj300_async.gateway")
#: The answer to a request for a drive a reload removed while it was on its way.
_GONE = WriteResult(
    Refusal.UNKNOWN_TARGET, "the drive is not served any more (the configuration was reloaded)"
)


@dataclass(slots=True)
class GatewayLine:
    """One line while the gateway runs: its bus, poller, drives and controller."""

    config: LineConfig
    profile: Profile
    bus: Bus[Any, Any]
    poller: Poller
    controller: Controller
    drives: dict[int, GatewayDrive]
    #: The line's utilisation, measured when a door asks for its health.
    meter: UtilisationMeter = field(default_factory=UtilisationMeter)
    #: What closes its bus (a reload closes one line alone).
    stack: contextlib.AsyncExitStack = field(default_factory=contextlib.AsyncExitStack)
    #: The task reading beside its poll (._beside), and the one its poller runs in.
    reader: asyncio.Task[None] | None = None
    runner: asyncio.Task[None] | None = None
    #: What a snapshot gives each trend column (._trend_columns).
    sample: Callable[[DriveSnapshot], tuple[float | None, ...]] | None = None

    def health(self, now: float | None = None) -> LineHealth:
        """The line's link, counters and utilisation at *now* (loop time; default: now).

        What a northbound shows of a line: never the bus itself (issue 42).
        """
        if now is None:
            now = asyncio.get_running_loop().time()
        return line_health(self.bus, self.drives.values(), self.meter, now)

    def traffic(self) -> LineTraffic:
        """The line's traffic, recorded from now until the recording's ``close()``.

        What a northbound may show of the wire (the workbench's line trace):
        never the bus itself (issue 42).
        """
        return LineTraffic(self.config.name, self.bus)


class Gateway:
    """The whole gateway (see the module docstring); the northbounds' :class:`GatewayView`."""

    def __init__(
        self, config: GatewayConfig, *, capture: str | None = None, tune_collector: bool = False
    ) -> None:
        self.config = config
        #: Tune Python's garbage collector for the process while this runs (._heap): the
        #: ``sj300 gateway`` command does (``--no-collector-tuning`` not), an application
        #: that embeds a Gateway decides for its own process, so the default is not to.
        self.tune_collector = tune_collector
        #: Where every line's frames go (``--capture``: one pcapng, one interface
        #: per line in the configuration's order), or None.
        self.capture_path = capture
        self._capture: CaptureFile | None = None
        self.lines: list[GatewayLine] = []
        self.audit = AuditLog(config.audit_log)
        #: The running northbounds by section name, in the order they started.
        self.northbounds: dict[str, Northbound] = {}
        self._drives: list[GatewayDrive] = []
        self._by_key: dict[tuple[str, int], GatewayDrive] = {}
        #: Exceptions a northbound's ``publish`` raised, by its section.
        self.publish_errors: dict[str, int] = {}
        #: Snapshots on their way to the northbounds (see ._batch).
        self._batch = SnapshotBatch(self._deliver)
        #: Reads beside the poll that failed, by (line, ``"trips"`` or ``"setpoint"``).
        self.read_errors: dict[tuple[str, str], int] = {}
        self._stack = contextlib.AsyncExitStack()
        self._reloading = asyncio.Lock()
        #: Each line's stack (its bus and poller), in the order they were opened.
        self._line_stacks: list[contextlib.AsyncExitStack] = []
        self._tasks: list[asyncio.Task[None]] = []
        #: The objects alive at start are out of the collector's way (._heap).
        self._frozen = False
        #: Reloads of the configuration (._reloader), by result: applied, refused.
        self.reloads: Counter[str] = Counter()
        #: False after a reload refused, until one is applied (a metric, an alert).
        self.last_reload_ok = True
        #: Northbounds a reload could not start (their section: why), for /healthz.
        self.northbound_failures: dict[str, str] = {}
        #: The event loop's lag, measured while the gateway runs (._looplag).
        self.loop_monitor = LoopMonitor(config.loop_lag_limit_s, every_second=_flush_logs)
        #: The log flood limit, while this gateway runs (._logflood).
        self._flood: FloodLimit | None = None
        #: The trip black box (.recorder), None when ``[recorder] enabled = false``.
        self.recorder = (
            TripRecorder(config.recorder, self.audit, config.gateway_id, self._recorded)
            if config.recorder.enabled
            else None
        )

    # -- what the northbounds see (GatewayView) --------------------------------------

    @property
    def drives(self) -> Sequence[GatewayDrive]:
        """Every drive, lines in the configuration's order, nodes ascending."""
        return self._drives

    def drive(self, line: str, node: int) -> GatewayDrive | None:
        """The drive *node* of line *line*, or None."""
        return self._by_key.get((line, node))

    @property
    def trip_records(self) -> TripStore | None:
        """The trip records kept, None when the recorder is off."""
        return None if self.recorder is None else self.recorder.store

    async def write(
        self,
        client: str,
        drive: GatewayDrive,
        request: WriteRequest,
        *,
        connection: str | None = None,
    ) -> WriteResult:
        """Judge and carry out *client*'s write through the drive's line (audited there)."""
        line = self._line_of(drive)
        if line is None:  # a reload removed its line while the request was on its way
            self.audit.write(client, drive, type(request).__name__, None, None, _GONE)
            return _GONE
        return await line.controller.write(client, drive, request, connection=connection)

    async def read_parameter_raw(self, drive: GatewayDrive, code: str) -> int:
        """Parameter *code* of *drive* read now, through its line's controller."""
        line = self._line_of(drive)
        if line is None:
            raise LocalProtocolError(_GONE.detail)
        return await line.controller.read_parameter_raw(drive, code)

    def disconnected(self, connection: str) -> None:
        """*connection* closed: the connection-scoped leases it holds lapse now."""
        for line in self.lines:
            line.controller.disconnected(connection)

    def refused(
        self, client: str, drive: GatewayDrive, what: str, value: object, result: WriteResult
    ) -> None:
        """Audit a request a northbound refused before handing it over."""
        self.audit.write(client, drive, what, None, value, result)

    def metrics(self) -> Iterator[Metric]:
        """The lines' and drives' families, then each northbound's (._gateway_metrics)."""
        return all_metrics(self)

    def problems(self) -> list[str]:
        """Why the gateway is not healthy (empty: every line is up, no lapse is pending)."""
        problems = line_problems(self._line_views())
        problems += self.loop_monitor.problems()
        for drive in self._drives:
            if drive.lapse_pending:
                why = f": {drive.lapse_error}" if drive.lapse_error else ""
                problems.append(
                    f"line {drive.line.name} {drive.profile.node_noun} {drive.node}: the lapsed "
                    f"lease's stop is not confirmed yet (try {drive.lapse_tries}{why})"
                )
        problems += [f"[{s}] is not running: {why}" for s, why in self.northbound_failures.items()]
        for northbound in self.northbounds.values():
            # Optional (Northbound's comment): MQTT's refused subscriptions, for one.
            problems += getattr(northbound, "problems", list)()
        return problems

    async def reload(self, config: GatewayConfig) -> ReloadOutcome:
        """Take *config* (read and checked) while running: what changed changes, and
        nothing else (:mod:`._reload`); one reload at a time."""
        async with self._reloading:
            return await apply_reload(self, config)

    async def reload_file(self, path: str | os.PathLike[str]) -> ReloadOutcome:
        """Read *path* and take it as :meth:`reload` does; a file that does not parse or
        check changes nothing (logged, counted: :mod:`._reloader`)."""
        async with self._reloading:
            return await reload_file(self, path)

    def _forget_drive(self, drive: GatewayDrive) -> None:
        """*drive* is served no more (its line is being removed): out of the maps."""
        self._drives.remove(drive)
        del self._by_key[drive.key]

    def _reorder_drives(self) -> None:
        """The drives in their lines' order again (a reload added or removed lines)."""
        self._drives[:] = [drive for line in self.lines for drive in line.drives.values()]

    def trend_window_s(self) -> float:
        """Seconds each drive's trend covers: the longest any part asks for (a
        northbound's ``trend_s``, the workbench's; the trip recorder's window), 0 when
        none does.

        Taken when a line opens: a reload that changes it applies to the lines it
        adds (docs/GATEWAY.md).
        """
        wanted = [float(getattr(s, "trend_s", 0.0)) for s in self.config.northbounds.values()]
        return max([self.config.recorder.window_s, *wanted])

    def _line_views(self) -> list[LineView]:
        return [LineView(line.config.name, line.bus) for line in self.lines]

    def _line_of(self, drive: GatewayDrive) -> GatewayLine | None:
        """*drive*'s line, None when a reload removed it (or replaced the drive)."""
        if self._by_key.get(drive.key) is not drive:
            return None
        return next((line for line in self.lines if line.config is drive.line), None)

    # -- running -----------------------------------------------------------------

    async def __aenter__(self) -> Gateway:
        self._flood = logflood.install()
        try:
            if self.capture_path is not None:
                self._capture = CaptureFile(self.capture_path)
                self._stack.callback(self._capture.close)
            self._stack.push_async_callback(self._close_lines)
            if self.recorder is not None:
                check_recorder(self.config.recorder)  # a file where its directory goes
                await self.recorder.start()
            buses = await self._open_buses(self.config.lines)
            for config, (bus, stack) in zip(self.config.lines, buses, strict=True):
                self.lines.append(self._open_line(config, bus, stack))
            tune = self.tune_collector
            # The northbounds' models: docstring of ._heap.
            with collector_paused() if tune else contextlib.nullcontext():
                for section, settings in self.config.northbounds.items():
                    await self._start_northbound(section, settings)
                if tune:  # before the collector runs again: it would scan it all once more
                    freeze_long_lived()
                    self._frozen = True
            if tune:
                self._stack.enter_context(young_collections_raised())
            for line in self.lines:
                await self._start_line(line)
            # From here: the start (an OPC UA address space built in one go) is not a
            # stall of the gateway serving, and /healthz must not call it one.
            self.loop_monitor.start()
        except BaseException:
            await self._shutdown()
            raise
        return self

    async def _start_northbound(self, section: str, settings: object) -> None:
        spec = get_northbound(section)
        northbound = spec.create(settings)
        try:
            await northbound.start(self)
        except GatewayStartError:
            raise
        except OSError as exc:  # a port in use, an address not on this host: one line
            endpoints = [endpoint for _, endpoint in spec.endpoints(settings)]
            raise GatewayStartError.of(section, endpoints, exc) from exc
        self.northbounds[section] = northbound

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._shutdown()

    async def _open_buses(
        self, configs: Sequence[LineConfig]
    ) -> list[tuple[Bus[Any, Any], contextlib.AsyncExitStack]]:
        """Each line's bus, opened at once: N lines that are down cost one connect time-out.

        A line that cannot connect is opened down (served offline, reconnected
        with its back-off); one whose settings are wrong raises, and the
        others are closed with the gateway. Each bus comes with the stack that
        closes it (the line's: a reload closes one line alone).
        """
        buses: dict[int, tuple[Bus[Any, Any], contextlib.AsyncExitStack]] = {}
        stacks: list[contextlib.AsyncExitStack] = []

        async def open_one(index: int, config: LineConfig) -> None:
            stack = contextlib.AsyncExitStack()
            stacks.append(stack)
            self._line_stacks.append(stack)  # closed with the gateway whatever happens
            bus: Bus[Any, Any] = await stack.enter_async_context(
                open_bus(
                    config.url,
                    protocol=config.protocol,
                    timeout=config.timeout_s,
                    capture=self._capture,
                    connect="background",  # a line down at start is served as one lost later
                )
            )
            buses[index] = (bus, stack)
            if not bus.connected:
                _log.warning("line %s: %s is down (%s): its drives are offline until it "
                             "connects", config.name, config.url, bus.link.last_error)  # fmt: skip

        try:
            async with asyncio.TaskGroup() as group:
                for index, config in enumerate(configs):
                    group.create_task(open_one(index, config))
        except BaseExceptionGroup as failed:  # the first line's error, as the caller expects
            for stack in stacks:  # the others opened here close now (a reload goes on)
                await stack.aclose()
                self._line_stacks.remove(stack)
            raise failed.exceptions[0] from None
        return [buses[index] for index in range(len(configs))]

    async def _close_lines(self) -> None:
        """Close every line's poller and bus, the last opened first."""
        while self._line_stacks:
            await self._line_stacks.pop().aclose()

    def _open_line(
        self, config: LineConfig, bus: Bus[Any, Any], stack: contextlib.AsyncExitStack
    ) -> GatewayLine:
        profile = get_profile(config.protocol)
        poller = Poller(
            interval_s=config.interval_s, reads=config.reads, parameters=config.parameters
        )
        poller.add(bus, config.nodes)
        stale_after_s = self.config.stale_after_s
        drives = {
            node: GatewayDrive(
                config, node, profile, Lease(config.lease_s), stale_after_s=stale_after_s
            )
            for node in config.nodes
        }
        window_s = self.trend_window_s()
        names = columns_of(config.parameters)
        if window_s > 0:
            capacity = trend_capacity(window_s, config.interval_s)
            for drive in drives.values():
                drive.trend = Trend(capacity, names)
        for drive in drives.values():
            self._drives.append(drive)
            self._by_key[drive.key] = drive
        controller = Controller(
            config, bus, self.audit, self._changed, polls=poller,
            stalled=self.loop_monitor.stalled,
        )  # fmt: skip
        line = GatewayLine(config, profile, bus, poller, controller, drives, stack=stack)
        line.sample = sample_of(config.parameters)
        if self.recorder is not None:
            self.recorder.add_line(line)
        poller.on_sample(lambda sample: self._on_sample(line, sample))
        _log.info("line %s: %s, %s %s", config.name, config.url, profile.node_noun,
                  ",".join(map(str, config.nodes)))  # fmt: skip
        return line

    async def _start_line(self, line: GatewayLine) -> None:
        """Start *line*'s poll and its reads beside it.

        The poller runs in a task of its own, entered and left there: its task group
        must be left by the task that entered it, and a reload starts and stops lines
        from its own task.
        """
        polling: asyncio.Future[None] = asyncio.get_running_loop().create_future()

        async def run() -> None:
            async with line.poller:
                polling.set_result(None)
                await asyncio.Future()  # until cancelled: leaving stops the poll

        runner = asyncio.create_task(run(), name=f"sj300-poll-{line.config.name}")
        self._tasks.append(runner)
        line.runner = runner
        await asyncio.wait([polling, runner], return_when=asyncio.FIRST_COMPLETED)
        if not polling.done():
            polling.cancel()
            await runner  # its start's error, raised here
        line.reader = asyncio.create_task(
            read_beside_the_poll(
                line, lambda: self.config.stale_after_s, self._changed, self.read_errors
            ),
            name=f"sj300-beside-{line.config.name}",
        )
        self._tasks.append(line.reader)

    async def _stop_line(self, line: GatewayLine) -> None:
        """Close *line*, already out of the gateway's maps: its held leases lapse first
        (their actions run and are waited for, as on the gateway's stop), then its reads,
        poller and bus end; its pending trip records are taken first."""
        if self.recorder is not None:
            self.recorder.remove_line(line)
        await line.controller.close(list(line.drives.values()))
        for task in (line.reader, line.runner):
            if task is not None:
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)
                self._tasks.remove(task)
        await line.stack.aclose()
        if line.stack in self._line_stacks:
            self._line_stacks.remove(line.stack)

    def _on_sample(self, line: GatewayLine, sample: Sample) -> None:
        drive = line.drives[sample.node]
        if self._by_key.get(drive.key) is not drive:
            return  # its line is being removed by a reload: served no more
        drive.readings.take(sample, line.profile)
        # The poll ended at sample.timestamp, on the loop's clock: the same instant in Unix time.
        now = asyncio.get_running_loop().time()
        snapshot = drive.rebuild(sample.timestamp, time.time() - (now - sample.timestamp))
        trend = drive.trend
        if trend is not None and snapshot.monitor_at != drive.trend_at and line.sample:
            # A new monitor read (._trend_columns). Its Unix time is worked out once, here:
            # recomputed from a later snapshot, the clocks' drift would move it.
            drive.trend_at = snapshot.monitor_at
            trend.add(snapshot.time - (snapshot.taken_at - snapshot.monitor_at),
                      *line.sample(snapshot))  # fmt: skip
        if self.recorder is not None:
            self.recorder.observe(drive, snapshot)
        self._publish(drive.served)

    def _changed(self, drive: GatewayDrive) -> None:
        """A write's read-back or a trip history changed *drive*'s readings: show it now.

        Never raises: the write or the trip read that called it goes on.
        """
        if self._by_key.get(drive.key) is not drive:
            return  # its line was removed by a reload (a lapse's stop ends on its own)
        try:
            snapshot = drive.rebuild(asyncio.get_running_loop().time())
            if self.recorder is not None:  # a history read shows a trip, or names it
                self.recorder.observe(drive, snapshot)
        except Exception:  # a profile's bug: the last snapshot stays, the caller goes on
            _log.exception("line %s node %d: no snapshot after a change", *drive.key)
            return
        # Out now, after what was gathered before it (see ._batch): someone is waiting.
        self._batch.add(drive.served)
        self._batch.flush()

    def _publish(self, served: ServedDrive) -> None:
        self._batch.add(served)

    def _recorded(self, summary: RecordSummary, drive: GatewayDrive) -> None:
        """A trip record was kept: the northbounds that announce one do (optional
        ``recorded``, ._northbound)."""
        if self._by_key.get(drive.key) is not drive:  # its line removed meanwhile: no door
            _log.debug("trip record %s kept, not announced: line %s is served no more",
                       summary.id, summary.line)  # fmt: skip
            return
        for section, northbound in self.northbounds.items():
            recorded = getattr(northbound, "recorded", None)
            if recorded is None:
                continue
            try:
                recorded(summary, drive.served)
            except Exception:  # its own failure: the record is kept, the others announce
                _log.exception("the %s northbound failed to announce a trip record", section)

    def _deliver(self, drives: list[ServedDrive]) -> None:
        """Each northbound takes *drives* (each a snapshot as served) in turn (see ._batch)."""
        for section, northbound in self.northbounds.items():
            publish = northbound.publish
            for served in drives:
                try:
                    publish(served)
                except Exception:  # its own failure: the others, and the caller, go on
                    count = self.publish_errors[section] = self.publish_errors.get(section, 0) + 1
                    if count == 1:
                        _log.exception("the %s northbound failed to take a snapshot", section)
                    else:
                        _log.debug("the %s northbound failed to take a snapshot (%d so far)",
                                   section, count, exc_info=True)  # fmt: skip
            flush = getattr(northbound, "flush", None)
            if flush is not None:  # the batch is whole: it sends it now (._northbound)
                try:
                    flush()
                except Exception:  # its own failure: the others go on
                    _log.exception("the %s northbound failed to flush", section)

    async def _shutdown(self) -> None:
        try:
            self._batch.flush()  # every snapshot made so far, before the northbounds close
            if self.recorder is not None:  # its pending records taken and written (bounded)
                await self.recorder.close()
            for section in reversed(list(self.northbounds)):
                northbound = self.northbounds.pop(section)
                try:
                    await northbound.close()
                except Exception:  # one northbound's failure must not leave the others running
                    _log.exception("the %s northbound failed to close", section)
            # Every line's lapses at once: their waits for confirmation do not add up.
            await asyncio.gather(
                *(line.controller.close(list(line.drives.values())) for line in self.lines)
            )
            for task in self._tasks:
                task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            self._tasks.clear()
            await self._stack.aclose()
            self._batch.flush()  # made while stopping: to no northbound, no timer left behind
        finally:
            # The process-wide parts, whatever happened above (an error, a cancellation):
            # left installed, they would outlive this gateway in its process.
            self.audit.close()
            self.loop_monitor.stop()
            if self._flood is not None:
                self._flood = None
                logflood.uninstall()
            if self._frozen:
                self._frozen = False
                thaw()

    def lines_by_name(self) -> Iterable[tuple[str, GatewayLine]]:
        """``(name, line)`` of every line, in the configuration's order."""
        return ((line.config.name, line) for line in self.lines)


def _flush_logs() -> None:
    limit = logflood.installed()
    if limit is not None:
        limit.flush()
