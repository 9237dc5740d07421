"""A line's health as the northbounds serve it: one frozen record, read from the line's bus.

A northbound sees a line's link, counters and utilisation through
:meth:`GatewayLine.health <sj300_async.gateway.GatewayLine.health>`, never
its bus (issue 42: a narrow northbound API). The figures are the bus's own
counters at the moment of the call, so two doors asked at once answer alike.

The utilisation is the share of the last second or so the line carried
bytes (:func:`~._metrics.busy_seconds` over the time between two marks at
least :data:`UTILISATION_WINDOW_S` apart), measured lazily when a door
asks: no timer of its own, and whichever door asks first advances the mark,
so every door shows the same figure. It is None until a window has passed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

from ._metrics import busy_seconds

if TYPE_CHECKING:
    from collections.abc import Iterable

    from ..bus import Bus
    from ._drive import GatewayDrive

__all__ = ["UTILISATION_WINDOW_S", "LineHealth", "UtilisationMeter", "line_health"]

#: The shortest span a utilisation figure covers, seconds.
UTILISATION_WINDOW_S: Final = 1.0


@dataclass(frozen=True, slots=True)
class LineHealth:
    """A line's link, counters and utilisation at one moment."""

    connected: bool
    drives: int
    #: Drives available: online by the poller's verdict and heard from at least once.
    drives_online: int
    #: Share of the last window the line carried bytes, 0..1; None before the first window.
    utilisation: float | None
    #: Wire time of every byte the line carried since it opened, seconds.
    busy_s: float
    requests: int
    replies: int
    timeouts: int
    retries: int
    naks: int
    transport_errors: int
    protocol_errors: int
    bad_frames: int
    early_frames: int
    stray_frames: int
    unsolicited_frames: int
    discarded_bytes: int
    connects: int
    disconnects: int
    #: Mean and greatest reply latency, seconds; None before the first reply.
    latency_mean_s: float | None
    latency_max_s: float | None


class UtilisationMeter:
    """A line's utilisation over its latest window (see the module docstring)."""

    __slots__ = ("_mark", "value")

    def __init__(self) -> None:
        self._mark: tuple[float, float] | None = None
        #: The latest figure, None before the first window.
        self.value: float | None = None

    def read(self, now: float, busy_s: float) -> float | None:
        """The utilisation, the mark moved on when a window has passed since it."""
        mark = self._mark
        if mark is None:
            self._mark = (now, busy_s)
        elif now - mark[0] >= UTILISATION_WINDOW_S:
            self.value = min(1.0, max(0.0, (busy_s - mark[1]) / (now - mark[0])))
            self._mark = (now, busy_s)
        return self.value


def line_health(
    bus: Bus[Any, Any], drives: Iterable[GatewayDrive], meter: UtilisationMeter, now: float
) -> LineHealth:
    """*bus*'s health now, with its *drives*' count and those online."""
    stats = bus.stats
    transactions = stats.transactions
    busy = busy_seconds(bus)
    total = online = 0
    for drive in drives:
        total += 1
        online += drive.snapshot.available
    return LineHealth(
        connected=bus.connected,
        drives=total,
        drives_online=online,
        utilisation=meter.read(now, busy),
        busy_s=busy,
        requests=transactions.requests,
        replies=transactions.replies,
        timeouts=transactions.timeouts,
        retries=transactions.retries,
        naks=sum(transactions.naks.values()),
        transport_errors=transactions.transport_errors,
        protocol_errors=transactions.protocol_errors,
        bad_frames=stats.bad_frames,
        early_frames=stats.early_frames,
        stray_frames=stats.stray_frames,
        unsolicited_frames=stats.unsolicited_frames,
        discarded_bytes=stats.discarded_bytes,
        connects=stats.connects,
        disconnects=stats.disconnects,
        latency_mean_s=transactions.latency_mean_s,
        latency_max_s=transactions.latency_max_s if transactions.replies else None,
    )
