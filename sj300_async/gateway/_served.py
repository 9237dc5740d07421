"""What a drive is as served: decided once, in the core, for every northbound.

A :class:`~sj300_async.profiles.DriveSnapshot` says what was read and when.
What a client is served of it is a judgement on top: is a value fresh
enough to show, what quality does it carry, what is the direction in
words, who holds the lease, is a lapse's stop still pending. Round 2 left
that judgement to each northbound, and five of them made it five ways
(issue 42). Here it is made once: the gateway builds one
:class:`ServedDrive` per snapshot (:meth:`GatewayDrive.rebuild
<sj300_async.gateway.GatewayDrive.rebuild>`), and every northbound turns
it into its own wire format, nothing more:

- **Freshness.** A group of values read together (status, monitor,
  direction, set frequency, trips, each parameter) is fresh until its read
  time plus the gateway's ``stale_after_s``. The trip history is read every
  ``trips_interval_s`` by plan, so it has that much more: a history read on
  time is never stale. (The set frequency, when it is not polled, is read
  twice per ``stale_after_s`` whatever ``setpoint_interval_s`` says, so it
  needs nothing more; OPC UA used to allow it ``setpoint_interval_s`` more
  than the other doors did.) The deadline
  is a loop time (:meth:`ServedDrive.fresh_until`), so a reader between
  samples (a Modbus or OPC UA read) compares one number.
- **Quality**, in this order (:meth:`ServedDrive.quality`): the drive is
  offline (the poller's verdict) :attr:`Quality.OFFLINE`; the value was
  never read :attr:`Quality.NEVER`; it was read but the drive does not
  give it (a parameter it refuses, an empty trip slot)
  :attr:`Quality.UNAVAILABLE`; it is older than its deadline
  :attr:`Quality.STALE` (the last usable value); else :attr:`Quality.GOOD`.
  Before the first sample there is no verdict yet: a value is
  :attr:`Quality.NEVER`, not offline.
  OPC UA's status codes, Modbus's validity bits, MQTT's and the API's nulls
  and the workbench's greying all come from it.
- **Values, masked** (:class:`ServedValues`): what a client that shows one
  value per field is served, with a stale or unavailable value None. At the
  sample by default (what the pushing northbounds send, cached: one build
  per snapshot), or at any loop time for a reader.
- **Words**: the direction (:data:`DIRECTION_WORDS`), the state (the
  profile's, in the snapshot), the present trip only while the status that
  says tripped is fresh.
- **The lease and the lapse**: who holds the lease (live: it changes between
  samples, and a Modbus read sees it), its seconds left, and whether a
  lapsed lease's stop is still unconfirmed (as of the snapshot: a change of
  it rebuilds the snapshot).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from ..profiles import DriveSnapshot, ParameterReading, ReadGroup, Trip
from ..wire import Direction

if TYPE_CHECKING:
    from ._drive import Lease

__all__ = ["DIRECTION_WORDS", "Quality", "ServedDrive", "ServedValues"]


class Quality(enum.IntEnum):
    """A served value's quality (see the module docstring for the order)."""

    GOOD = 0
    #: Read, but longer ago than its deadline: the last usable value.
    STALE = 1
    #: The poller holds the drive offline.
    OFFLINE = 2
    #: Never read yet.
    NEVER = 3
    #: Read, but the drive does not give it (a refused parameter, an empty trip slot).
    UNAVAILABLE = 4


#: A direction in the words every northbound serves it in.
DIRECTION_WORDS: Final[Mapping[Direction, str]] = {
    Direction.STOP: "stop",
    Direction.FORWARD: "forward",
    Direction.REVERSE: "reverse",
}


@dataclass(frozen=True, slots=True)
class ServedValues:
    """A drive's values as served at one instant: None where stale, unavailable or unread.

    ``parameters`` holds every polled parameter read at least once: None when
    stale or refused; one never read is left out (the gateway polls it before
    it knows it).
    """

    #: Online and heard from (the snapshot's ``available``).
    online: bool
    #: Seconds since the last good sample, None before the first.
    sample_age_s: float | None
    state: str | None
    running: bool | None
    tripped: bool | None
    status_fields: Mapping[str, object] | None
    #: ``"stop"``, ``"forward"``, ``"reverse"`` (:data:`DIRECTION_WORDS`).
    direction: str | None
    output_frequency_hz: float | None
    output_current_a: float | None
    output_voltage_v: float | None
    output_torque_percent: float | None
    power_kw: float | None
    set_frequency_hz: float | None
    #: The trip the drive is in, while its status says so and is fresh.
    trip: Trip | None
    parameters: Mapping[str, ParameterReading | None]


class ServedDrive:
    """One drive as served, built once per snapshot (see the module docstring)."""

    __slots__ = (
        "_at_sample",
        "_frequency_limit",
        "_lease",
        "_online",
        "_parameter_window_s",
        "direction_until",
        "lapse_pending",
        "monitor_until",
        "sample_until",
        "set_frequency_until",
        "snapshot",
        "stale_after_s",
        "status_until",
        "trips_until",
        "verdict",
    )

    def __init__(
        self,
        snapshot: DriveSnapshot,
        *,
        stale_after_s: float,
        lease: Lease | None = None,
        lapse_pending: bool = False,
        trips_interval_s: float = 0.0,
        verdict: bool = True,
        frequency_limit: tuple[str | None, float] = (None, math.inf),
    ) -> None:
        """*verdict*: the snapshot's ``online`` is the poller's verdict (False before the
        drive's first poll: then no value is offline, only not read yet).
        *frequency_limit*: the profile's maximum-frequency parameter and its highest
        frequency (:meth:`max_frequency_hz`)."""
        s = snapshot
        self._online = s.online or not verdict or s.taken_at == -math.inf
        self.snapshot = s
        self.stale_after_s = stale_after_s
        self._parameter_window_s = stale_after_s
        #: Loop time until which each group is fresh (-inf: never read).
        self.status_until = s.status_at + stale_after_s
        self.monitor_until = s.monitor_at + stale_after_s
        self.direction_until = s.direction_at + stale_after_s
        self.set_frequency_until = s.set_frequency_at + stale_after_s
        self.trips_until = s.trips_at + stale_after_s + trips_interval_s
        #: Loop time until which the sample itself, the poller's verdict, is fresh.
        self.sample_until = s.taken_at + stale_after_s
        #: The snapshot's ``online`` is the poller's verdict (False before its first poll).
        self.verdict = verdict
        self.lapse_pending = lapse_pending
        self._lease = lease
        self._frequency_limit = frequency_limit
        self._at_sample: ServedValues | None = None

    # -- freshness and quality --------------------------------------------------------

    def fresh_until(self, group: ReadGroup) -> float:
        """Loop time until which *group*'s values are fresh (-inf: never read)."""
        until: float = getattr(self, f"{group}_until")
        return until

    def fresh(self, group: ReadGroup, now: float) -> bool:
        """True when *group*'s values are fresh at loop time *now*."""
        return now <= self.fresh_until(group)

    def quality(self, group: ReadGroup, now: float, *, present: bool = True) -> Quality:
        """The quality of a value of *group* at loop time *now*.

        *present*: the read gave the value (False: the drive does not give it,
        e.g. an empty trip slot, a monitor without torque).
        """
        s = self.snapshot
        return _quality(
            self._online, getattr(s, f"{group}_at"), self.fresh_until(group), present, now
        )

    def verdict_quality(self, now: float) -> Quality:
        """The quality of the poller's verdict itself (the drive online or not) at *now*.

        Never offline (it is the verdict): never read before the first sample,
        good while samples keep coming, stale once the last is older than
        ``stale_after_s`` (a stalled poller's last verdict ages).
        """
        if self.snapshot.taken_at == -math.inf:
            return Quality.NEVER
        return Quality.GOOD if now <= self.sample_until else Quality.STALE

    def parameter_until(self, code: str) -> float:
        """Loop time until which polled parameter *code* is fresh (-inf: never read, or refused).

        A parameter's :meth:`fresh_until`: a reader between samples (a Modbus
        read, and its cache of answers) compares one number.
        """
        reading = self.snapshot.parameters.get(code)
        return -math.inf if reading is None else reading.at + self._parameter_window_s

    def parameter_quality(self, code: str, now: float) -> Quality:
        """The quality of polled parameter *code* at loop time *now*."""
        s = self.snapshot
        reading = s.parameters.get(code)
        if reading is None:
            refused = code in s.unavailable_parameters
            return _quality(self._online, 0.0 if refused else -math.inf, math.inf, False, now)
        online = self._online
        return _quality(online, reading.at, reading.at + self._parameter_window_s, True, now)

    # -- values ------------------------------------------------------------------------

    def values(self, now: float | None = None) -> ServedValues:
        """The values as served at loop time *now* (default: at the sample, built once)."""
        if now is None:
            if self._at_sample is None:
                self._at_sample = self._values(self.snapshot.taken_at)
            return self._at_sample
        return self._values(now)

    def _values(self, now: float) -> ServedValues:
        s = self.snapshot
        status = now <= self.status_until
        monitor = now <= self.monitor_until
        window = self._parameter_window_s
        parameters: dict[str, ParameterReading | None] = {
            code: reading if now - reading.at <= window else None
            for code, reading in s.parameters.items()
        }
        for code in s.unavailable_parameters:
            parameters[code] = None
        direction = s.direction
        return ServedValues(
            online=s.available,
            sample_age_s=s.sample_age_s(now),
            state=s.state if status else None,
            running=s.running if status else None,
            tripped=s.tripped if status else None,
            status_fields=s.status_fields if status else None,
            direction=(
                DIRECTION_WORDS.get(direction)
                if direction is not None and now <= self.direction_until
                else None
            ),
            output_frequency_hz=s.output_frequency_hz if monitor else None,
            output_current_a=s.output_current_a if monitor else None,
            output_voltage_v=s.output_voltage_v if monitor else None,
            output_torque_percent=s.output_torque_percent if monitor else None,
            power_kw=s.power_kw if monitor else None,
            set_frequency_hz=s.set_frequency_hz if now <= self.set_frequency_until else None,
            trip=s.trip if status and s.tripped else None,
            parameters=parameters,
        )

    @property
    def highest_frequency_hz(self) -> float:
        """The protocol's highest frequency (what :meth:`max_frequency_hz` is at most)."""
        return self._frequency_limit[1]

    def max_frequency_hz(self) -> float:
        """The highest frequency the drive takes: its own maximum-frequency parameter when
        the line polls it and it was read (at most the protocol's highest), else the
        protocol's highest. The controller refuses above the same (with the reason)."""
        code, highest = self._frequency_limit
        reading = None if code is None else self.snapshot.parameters.get(code)
        return highest if reading is None else min(reading.value, highest)

    # -- the lease ----------------------------------------------------------------------

    def lease_holder(self, now: float) -> str | None:
        """Who holds the drive's lease at loop time *now* (None: nobody, or no lease)."""
        lease = self._lease
        return lease.holder if lease is not None and lease.held(now) else None

    def lease_seconds_left(self, now: float) -> float:
        """Seconds until the lease lapses at *now* (0 when nobody holds it)."""
        lease = self._lease
        return 0.0 if lease is None or not lease.held(now) else lease.seconds_left(now)


def _quality(online: bool, at: float, until: float, present: bool, now: float) -> Quality:
    if not online:
        return Quality.OFFLINE
    if at == -math.inf:
        return Quality.NEVER
    if not present:
        return Quality.UNAVAILABLE
    if now > until:
        return Quality.STALE
    return Quality.GOOD
