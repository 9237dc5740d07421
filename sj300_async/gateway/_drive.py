"""One drive while the gateway serves it: its readings, its latest snapshot, its lease.

The gateway keeps one :class:`GatewayDrive` per configured drive. Samples
and the read-backs of writes go into its
:class:`~sj300_async.profiles.DriveReadings`; after each, the gateway
builds a new :class:`~sj300_async.profiles.DriveSnapshot` (:meth:`rebuild`)
and hands it to every northbound. Northbounds read a drive through this
object: ``snapshot`` (the latest), ``served`` (the same as served: the
gateway's judgement of its values, :mod:`._served`), ``lease`` (live: a Modbus read of the
lease registers sees it change between samples), ``line`` (its line's
configuration: write grants), ``profile`` and ``unit``. They never write
to it: writes go through the gateway (:meth:`~._northbound.GatewayView.write`).

Its ``trend`` (:mod:`._trend`, :mod:`._trend_columns`) is the core's: the
gateway adds each monitor read to it; the workbench graphs it and a trip
record (:mod:`.recorder`) keeps the part around the trip.

The lease (:class:`Lease`) and the lapse's progress are plain state here;
:mod:`._control` takes and renews the lease and :mod:`._lapse` runs the
lapse action.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from ..profiles import NEVER, DriveReadings, DriveSnapshot, Profile, build_snapshot
from ._model import DEFAULT_STALE_AFTER_S, LineConfig
from ._served import ServedDrive
from ._trend import Trend

__all__ = ["GatewayDrive", "Lease"]


@dataclass(slots=True)
class Lease:
    """Who may send run and frequency commands to one drive, and until when."""

    #: How long a heartbeat keeps the lease, in seconds.
    duration_s: float
    #: The client holding it (its IP address, ``"mqtt"``), or None.
    holder: str | None = None
    #: Event-loop time at which it lapses (meaningless without a holder).
    expires_at: float = -math.inf
    #: The connection the holder's last heartbeat came by (its northbound's
    #: name for it), or None: a connection-scoped lease lapses when it closes.
    connection: str | None = None
    #: The loop's stalled seconds (._looplag) at the last heartbeat, and the seconds of
    #: stall added to ``expires_at`` since: the gateway's own stall is not lease time.
    stalled_at: float = 0.0
    credited_s: float = 0.0

    def held_by(self, client: str, now: float) -> bool:
        """True when *client* holds the lease at *now*."""
        return self.holder == client and now < self.expires_at

    def held(self, now: float) -> bool:
        """True when someone holds the lease at *now*."""
        return self.holder is not None and now < self.expires_at

    def seconds_left(self, now: float) -> float:
        """Seconds until the lease lapses (0 when nobody holds it)."""
        return max(0.0, self.expires_at - now) if self.holder is not None else 0.0


@dataclass(slots=True, eq=False)
class GatewayDrive:
    """One drive of the gateway (see the module docstring)."""

    line: LineConfig
    node: int
    profile: Profile
    lease: Lease
    readings: DriveReadings = field(default_factory=DriveReadings)
    #: The gateway's ``stale_after_s``: how old a value may be and still be served.
    stale_after_s: float = DEFAULT_STALE_AFTER_S
    #: The latest snapshot (one with nothing read before the first sample).
    snapshot: DriveSnapshot = field(init=False)
    #: The latest snapshot as served (:mod:`._served`): built with it, what every
    #: northbound serves.
    served: ServedDrive = field(init=False)
    #: A lapsed lease's stop is not confirmed yet (it is being retried).
    lapse_pending: bool = False
    #: Why the pending lapse's last try failed ("" before the first failure).
    lapse_error: str = ""
    #: Tries of the pending lapse's stop so far.
    lapse_tries: int = 0
    #: Its recent samples (every polled field), None when nothing needs them (no
    #: workbench, no recorder): the gateway's, fed on each new monitor read.
    trend: Trend | None = None
    #: The loop time of the monitor read the trend's newest sample is.
    trend_at: float = NEVER

    def __post_init__(self) -> None:
        self.snapshot = self._build(now=-math.inf, wall=0.0)
        self.served = self._serve(self.snapshot)

    @property
    def unit(self) -> int:
        """The drive's unit id (Modbus unit; docs/GATEWAY.md)."""
        return self.line.unit(self.node)

    @property
    def key(self) -> tuple[str, int]:
        """``(line name, node)``: the drive's name in the gateway."""
        return self.line.name, self.node

    def rebuild(self, now: float, wall: float | None = None) -> DriveSnapshot:
        """A new snapshot from the readings at loop time *now* (Unix time *wall*, default now),
        and the drive as served with it."""
        self.snapshot = snapshot = self._build(now, time.time() if wall is None else wall)
        self.served = self._serve(snapshot)
        return snapshot

    def _serve(self, snapshot: DriveSnapshot) -> ServedDrive:
        return ServedDrive(
            snapshot,
            stale_after_s=self.stale_after_s,
            lease=self.lease,
            lapse_pending=self.lapse_pending,
            trips_interval_s=self.line.trips_interval_s,
            verdict=self.readings.polled,
            frequency_limit=(self.profile.max_frequency_parameter, self.profile.max_frequency_hz),
        )

    def _build(self, now: float, wall: float) -> DriveSnapshot:
        return build_snapshot(
            self.profile,
            self.readings,
            line=self.line.name,
            node=self.node,
            unit=self.unit,
            now=now,
            wall=wall,
        )
