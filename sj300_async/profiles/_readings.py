"""What is known of one drive: each read's latest result, with the time it was read.

:class:`DriveReadings` is the cache a snapshot is built from
(:func:`~._build.build_snapshot`): the gateway keeps one per drive and feeds
it every sample and every write's read-back; the command line's monitor
feeds it its samples. It holds the drive class's own results (an
``InverterStatus``, an ``Fr700Status``...) and their neutral views, which
the profile computes once, when a result arrives.

Decisions:

- A poll's result replaces what was known, with the poll's time, except a
  value learnt after the poll began (a write's read-back): the poll may
  have read it before the write, and the newer one stays.
- A failed read keeps the last good value and its old time: it goes stale,
  it is never replaced by a guess.
- A parameter the drive refused to read (the poll's ``unavailable``) has no
  value at all from then on, not a stale one, until it reads again: the
  drive said it has none to give. It is kept in :attr:`DriveReadings.unavailable`.
- Parameters are kept as the drive's integers (exact, what a register map
  serves); a poll gives values in their unit, turned back into integers
  by the catalogue (:func:`raw_value`).
- ``tripped_since`` is the loop time the drive was first seen tripped:
  a trip history read before it names the previous trip, not this one.
"""

from __future__ import annotations

from collections.abc import Mapping
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field
from typing import Any, Protocol

from ..wire import LocalProtocolError
from ._profile import ParameterSpec, Profile
from ._snapshot import NEVER, MonitorView, StatusView, TripLog

__all__ = ["DriveReadings", "PollResult", "raw_value"]


class PollResult(Protocol):
    """What a poll of one drive gave (the poller's ``Sample`` is one)."""

    @property
    def online(self) -> bool: ...
    @property
    def error(self) -> str | None: ...
    @property
    def started(self) -> float: ...
    @property
    def timestamp(self) -> float: ...
    @property
    def status(self) -> Any: ...
    @property
    def monitor(self) -> Any: ...
    @property
    def parameters(self) -> Mapping[str, float]: ...
    @property
    def unavailable(self) -> AbstractSet[str]:
        """The parameters the drive refused to read (none was read)."""


def raw_value(spec: ParameterSpec, value: float) -> int:
    """The drive's integer of *value* in *spec*'s unit.

    A value outside the catalogue's range is still the drive's (it holds
    it, whatever the catalogue says): counted in the increment all the same.
    """
    try:
        return int(spec.to_raw(value))
    except LocalProtocolError:
        return round(value * int(spec.scale))


@dataclass(slots=True)
class DriveReadings:
    """The latest result of each read of one drive (see the module docstring)."""

    #: The poller's verdict after the latest poll.
    online: bool = False
    #: A poll's result was taken: ``online`` is the poller's verdict (before, it is
    #: no verdict at all, whatever it says).
    polled: bool = False
    #: Loop time of the latest poll in which every read succeeded (None: never).
    last_ok: float | None = None
    status: Any = None
    status_view: StatusView | None = None
    status_at: float = NEVER
    monitor: Any = None
    monitor_view: MonitorView | None = None
    monitor_at: float = NEVER
    #: Parameters as the drive's integers, and when each was read.
    parameters: dict[str, int] = field(default_factory=dict)
    parameters_at: dict[str, float] = field(default_factory=dict)
    #: Polled parameters the drive refused at their latest read: no value.
    unavailable: set[str] = field(default_factory=set)
    set_frequency_hz: float | None = None
    set_frequency_at: float = NEVER
    #: The trip history as the drive class read it, and its neutral form.
    trips: Any = None
    trip_log: TripLog | None = None
    trips_at: float = NEVER
    #: Loop time the drive was first seen tripped, None while it is not.
    tripped_since: float | None = None

    def take(self, poll: PollResult, profile: Profile) -> None:
        """Take a poll's results (see the module docstring)."""
        now, began = poll.timestamp, poll.started
        self.online = poll.online
        self.polled = True
        if poll.error is None:
            self.last_ok = now
        if poll.status is not None and self.status_at <= began:
            self.set_status(poll.status, now, profile)
        if poll.monitor is not None and self.monitor_at <= began:
            self.set_monitor(poll.monitor, now, profile)
        parameters = poll.parameters
        if parameters:
            catalogue = profile.parameters
            for code, value in parameters.items():
                if self.parameters_at.get(code, NEVER) <= began:
                    self.set_parameter(code, raw_value(catalogue.spec(code), value), now)
            setpoint = profile.setpoint_parameter
            if setpoint is not None and setpoint in parameters and self.set_frequency_at <= began:
                self.set_frequency(parameters[setpoint], now)
        for code in poll.unavailable:
            if self.parameters_at.get(code, NEVER) <= began:  # else read since: it stays
                self.parameters.pop(code, None)
                self.parameters_at.pop(code, None)
                self.unavailable.add(code)

    def set_status(self, status: Any, at: float, profile: Profile) -> None:
        """A status read at loop time *at*."""
        view = profile.status_view(status)
        self.status, self.status_view, self.status_at = status, view, at
        if not view.tripped:
            self.tripped_since = None
        elif self.tripped_since is None:
            self.tripped_since = at

    def set_monitor(self, monitor: Any, at: float, profile: Profile) -> None:
        """A monitor read at loop time *at*."""
        self.monitor, self.monitor_view, self.monitor_at = (
            monitor,
            profile.monitor_view(monitor),
            at,
        )

    def set_parameter(self, code: str, raw: int, at: float) -> None:
        """A parameter's integer read at loop time *at*."""
        self.parameters[code] = raw
        self.parameters_at[code] = at
        self.unavailable.discard(code)

    def set_frequency(self, hz: float, at: float) -> None:
        """The set frequency read back at loop time *at*."""
        self.set_frequency_hz, self.set_frequency_at = hz, at

    def set_trips(self, history: Any, at: float, profile: Profile) -> None:
        """A trip history read at loop time *at*."""
        self.trips, self.trip_log, self.trips_at = history, profile.trip_log(history), at
