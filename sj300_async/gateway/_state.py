"""What the gateway knows about each drive: the poll cache, and the control lease.

One :class:`DriveState` per drive, fed by the poller's samples (and by the
read-backs of the gateway's own writes). Every block of data carries the
event-loop time it was read at, so that a Modbus read can refuse data older
than the staleness limit instead of serving it as current. A failed poll
keeps the last good values and their old times: they go stale, they are
never replaced by a guess.

The lease (:class:`Lease`) is plain state here; :mod:`._control` takes and
renews it and runs the lapse action.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .._poller import Sample
from ..fr700 import Fr700Monitor, Fr700Status
from ..sj300 import InverterStatus, MonitorData, TripHistory

__all__ = ["DriveState", "Lease"]


@dataclass(slots=True)
class Lease:
    """Who may send run and frequency commands to one drive, and until when."""

    #: How long a heartbeat keeps the lease, in seconds.
    duration_s: float
    #: The client holding it (its IP address), or None.
    holder: str | None = None
    #: Event-loop time at which it lapses (meaningless without a holder).
    expires_at: float = -math.inf

    def held_by(self, client: str, now: float) -> bool:
        """True when *client* holds the lease at *now*."""
        return self.holder == client and now < self.expires_at

    def held(self, now: float) -> bool:
        """True when someone holds the lease at *now*."""
        return self.holder is not None and now < self.expires_at

    def seconds_left(self, now: float) -> float:
        """Seconds until the lease lapses (0 when nobody holds it)."""
        return max(0.0, self.expires_at - now) if self.holder is not None else 0.0


@dataclass(slots=True)
class DriveState:
    """One drive as the gateway serves it (see the module docstring)."""

    line: str
    node: int
    unit: int
    protocol: str
    lease: Lease
    #: The poller's verdict (offline after its ``offline_after`` failed polls).
    online: bool = False
    #: Event-loop time of the last poll in which every read succeeded.
    last_ok: float | None = None
    status: InverterStatus | Fr700Status | None = None
    status_at: float = -math.inf
    monitor: MonitorData | Fr700Monitor | None = None
    monitor_at: float = -math.inf
    #: Polled parameters as raw integers (the value counted in its increment).
    parameters: dict[str, int] = field(default_factory=dict)
    parameters_at: dict[str, float] = field(default_factory=dict)
    #: The set frequency, as last read back (SJ300: also F001 when polled).
    set_frequency_hz: float | None = None
    set_frequency_at: float = -math.inf
    trips: TripHistory | None = None
    trips_at: float = -math.inf
    #: The register map's encoding of each field, with the read time it was
    #: encoded for (see :meth:`~._registers.RegisterMap.read`): every change of
    #: a value above comes with a new time, which invalidates it.
    encoded: dict[int, tuple[float, list[int] | None]] = field(default_factory=dict)

    def update(self, sample: Sample, raw_parameters: dict[str, int]) -> None:
        """Take a poll's results: what it read replaces what was known, with its time.

        Except a value learnt after the poll began (a write's read-back): the
        poll may have read it before the write, and the newer one stays.
        """
        now, began = sample.timestamp, sample.started
        self.online = sample.online
        if sample.error is None:
            self.last_ok = now
        if sample.status is not None and self.status_at <= began:
            self.status, self.status_at = sample.status, now
        if sample.monitor is not None and self.monitor_at <= began:
            self.monitor, self.monitor_at = sample.monitor, now
        for code, raw in raw_parameters.items():
            if self.parameters_at.get(code, -math.inf) <= began:
                self.parameters[code] = raw
                self.parameters_at[code] = now
        if "F001" in raw_parameters and self.protocol == "sj300" and self.set_frequency_at <= began:
            self.set_frequency_hz = raw_parameters["F001"] / 100
            self.set_frequency_at = now

    def sample_age_s(self, now: float) -> float | None:
        """Seconds since the last good sample, None before the first."""
        return None if self.last_ok is None else max(0.0, now - self.last_ok)

    @property
    def running(self) -> bool | None:
        """True while the drive outputs, from its status (None when unknown)."""
        status = self.status
        if isinstance(status, InverterStatus):
            return status.b.value == 1  # StatusB.RUNNING
        if isinstance(status, Fr700Status):
            return status.running
        return None

    @property
    def tripped(self) -> bool | None:
        """True while a trip is latched, from its status (None when unknown)."""
        return None if self.status is None else self.status.tripped
