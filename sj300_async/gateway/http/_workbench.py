"""The workbench's state: the event hub, the lines' counters as JSON, the drives' trends.

One :class:`Workbench` per HTTP northbound. It is fed by the northbound's
``publish`` (every drive snapshot: the open event streams get it encoded
once) and by its own ticker, which
sends every line's counters once per :data:`LINE_EVENT_S`. The API
(:mod:`._api`) reads it.

Decisions:

- A drive event is encoded only when some stream is open: with no
  workbench page open, a sample costs nothing here.
- A drive's trend is the core's (``GatewayDrive.trend``, which the
  gateway sizes to cover ``trend_s`` at least): the workbench serves its
  last ``trend_s`` and its frequency, current and voltage.
- What a drive is as served comes from the gateway's served view
  (:class:`~sj300_async.gateway.ServedDrive`), never judged here: a pushed
  event carries the values as of the sample (``served.values()``, built once
  and shared with the other northbounds), a GET and a new stream's first
  frames the values as of the request; the lease holder and its seconds left
  are the served drive's, at the moment the JSON is written.
- A line's link, counters and utilisation are the core's health of the
  line (``ServedLine.health``), the same figures OPC UA serves; the
  utilisation is the share of the last second or so the line carried bytes,
  the figure ``rate(sj300_line_busy_seconds_total[1s])`` would give.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence
from typing import Any, Final

from ...version import __version__
from .. import TREND_VALUES as VALUES
from .. import GatewayDrive, GatewayView, ServedDrive, ServedLine, trend_capacity
from ._events import EventHub, sse_frame
from ._json import Json, drive_json
from ._linetrace import LineTrace

__all__ = ["LINE_EVENT_S", "Workbench"]

#: Seconds between two events of each line's counters.
LINE_EVENT_S: Final = 1.0


class Workbench:
    """What the workbench's API and event stream serve (see the module docstring)."""

    def __init__(
        self,
        gateway: GatewayView,
        trend_s: float,
        *,
        writes: bool = False,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.gateway = gateway
        self.trend_s = trend_s
        #: The routes that write exist (module _write_api).
        self.writes = writes
        self.hub = EventHub()
        self._clock = clock or asyncio.get_running_loop().time
        #: Each line's recent traffic (the line page; kept by the line's bus's recorder).
        self.traces: dict[str, LineTrace] = {
            line.config.name: LineTrace(line.traffic()) for line in gateway.lines
        }

    def now(self) -> float:
        return self._clock()

    # -- drives ----------------------------------------------------------------------------

    def trend(
        self, drive: GatewayDrive, since: float | None = None
    ) -> tuple[int, dict[str, list[float | None]]]:
        """*drive*'s trend as the workbench serves it: its capacity over ``trend_s``,
        and the time, frequency, current and voltage of its samples newer than *since*."""
        capacity = trend_capacity(self.trend_s, drive.line.interval_s)
        if drive.trend is None:  # a line kept by a reload that added [http]: none kept
            return capacity, {name: [] for name in ("time", *VALUES)}
        columns = drive.trend.columns(since, last=capacity)
        return capacity, {name: columns[name] for name in ("time", *VALUES)}

    def publish(self, served: ServedDrive) -> None:
        """A drive's new snapshot: to every open stream."""
        snapshot = served.snapshot
        if len(self.hub):
            self.hub.publish(
                f"drive/{snapshot.line}/{snapshot.node}",
                sse_frame("drive", self.drive_json(served, at_sample=True)),
                wake=False,  # sent at the batch's flush
            )

    def drive_json(self, served: ServedDrive, *, at_sample: bool = False) -> Json:
        """*served* as JSON: its values as of the sample (a push) or as of now (a GET)."""
        now = self.now()
        snapshot = served.snapshot
        data = drive_json(snapshot, served.values() if at_sample else served.values(now))
        # Who controls it (the lease), so every page shows it: live, as of now.
        data["control"] = {
            "holder": served.lease_holder(now),
            "seconds_left": served.lease_seconds_left(now),
        }
        drive = self.gateway.drive(snapshot.line, snapshot.node)
        if drive is not None and drive.trend is not None and snapshot.monitor_at == drive.trend_at:
            data["monitor_time"] = drive.trend.last_time  # the trend's own time of this read
        return data

    # -- lines -----------------------------------------------------------------------------

    def line_json(self, line: ServedLine) -> Json:
        """A line's link and counters, and its utilisation (the core's health of the line)."""
        health = line.health(self.now())
        return {
            "name": line.config.name,
            "protocol": line.config.protocol,
            "url": line.config.url,
            "interval_s": line.config.interval_s,
            "connected": health.connected,
            "drives": health.drives,
            "drives_online": health.drives_online,
            "utilisation": health.utilisation,
            "requests": health.requests,
            "replies": health.replies,
            "timeouts": health.timeouts,
            "retries": health.retries,
            "naks": health.naks,
            "transport_errors": health.transport_errors,
            "protocol_errors": health.protocol_errors,
            "bad_frames": health.bad_frames,
            "early_frames": health.early_frames,
            "stray_frames": health.stray_frames,
            "unsolicited_frames": health.unsolicited_frames,
            "discarded_bytes": health.discarded_bytes,
            "connects": health.connects,
            "disconnects": health.disconnects,
            "latency_mean_s": health.latency_mean_s,
            "latency_max_s": health.latency_max_s,
        }

    def tick_lines(self) -> None:
        """Send each line's counters to the pages that follow it (its health moves the
        utilisation's mark on, whoever asks)."""
        now = self.now()
        for line in self.gateway.lines:
            if len(self.hub):
                self.hub.publish(
                    f"line/{line.config.name}", sse_frame("line", self.line_json(line))
                )
            else:
                line.health(now)  # the utilisation is measured even with no page open

    def lines_changed(self, added: Sequence[ServedLine], removed: Sequence[ServedLine]) -> None:
        """A reload added or removed lines: their traces made or dropped (a replaced
        line's is new: what it recorded was of the line as it was)."""
        for line in removed:
            trace = self.traces.pop(line.config.name, None)
            if trace is not None:
                trace.close()
        for line in added:
            self.traces[line.config.name] = LineTrace(line.traffic())

    def close(self) -> None:
        """Stop recording the lines, end the event streams."""
        for trace in self.traces.values():
            trace.close()
        self.hub.close()

    async def run(self) -> None:
        """Tick the lines every :data:`LINE_EVENT_S` until cancelled."""
        while True:
            self.tick_lines()
            await asyncio.sleep(LINE_EVENT_S)

    # -- the gateway -----------------------------------------------------------------------

    def gateway_json(self) -> Json:
        config = self.gateway.config
        return {
            "id": config.gateway_id,
            "version": __version__,
            "time": time.time(),
            "stale_after_s": config.stale_after_s,
            "trend_s": self.trend_s,
            "writes": self.writes,
            "lines": [
                {
                    "name": line.name,
                    "protocol": line.protocol,
                    "nodes": list(line.nodes),
                    "interval_s": line.interval_s,
                    "lease_s": line.lease_s,
                    # What may be written, where writes are served at all.
                    "grants": [
                        {
                            "nodes": sorted(grant.nodes),
                            "control": grant.control,
                            "parameters": sorted(grant.parameters),
                        }
                        for grant in line.grants
                    ]
                    if self.writes
                    else [],
                }
                for line in config.lines
            ],
        }

    def everything(self) -> list[tuple[str, bytes]]:
        """Every subject's frame as of now: what a new stream starts with."""
        out: list[tuple[str, bytes]] = [("gateway", sse_frame("gateway", self.gateway_json()))]
        for line in self.gateway.lines:
            out.append((f"line/{line.config.name}", sse_frame("line", self.line_json(line))))
        for drive in self.gateway.drives:
            served = drive.served
            subject = f"drive/{served.snapshot.line}/{served.snapshot.node}"
            out.append((subject, sse_frame("drive", self.drive_json(served))))
        return out

    def extra(self) -> dict[str, Any]:
        """The event hub's counters (for the northbound's metrics)."""
        return {"streams": len(self.hub), "sent": self.hub.sent, "replaced": self.hub.replaced}
