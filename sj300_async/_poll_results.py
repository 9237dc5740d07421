"""What the poller reports: a drive's :class:`Sample`, its :class:`DriveHealth`, a bus's
:class:`BusPollStats` (the poller itself and its rules: :mod:`._poller`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from .fr700 import Fr700Monitor, Fr700Status
from .sj300 import InverterStatus, MonitorData

__all__ = ["BusPollStats", "DriveHealth", "Sample"]


@dataclass(frozen=True, slots=True)
class Sample:
    """The result of polling one drive once."""

    bus: str  #: the bus's description, e.g. ``tcp://127.0.0.1:4001``
    node: int
    timestamp: float  #: event-loop time of the poll's end
    online: bool  #: the drive's health after this poll (see ``answered``)
    status: InverterStatus | Fr700Status | None  #: None when not read or failed
    monitor: MonitorData | Fr700Monitor | None  #: None when not read or failed
    parameters: Mapping[str, float]  #: the parameters read, engineering values
    error: str | None  #: the poll's error, None when every read succeeded
    latency_s: float | None  #: mean time per successful read of this poll
    #: The drive has answered at least once, this poll or before (False: never heard from).
    answered: bool = False
    #: Event-loop time of the poll's start: its values were read between this
    #: and ``timestamp`` (a cache that also learns values elsewhere, like the
    #: gateway's write read-backs, keeps those learnt after this).
    started: float = 0.0
    #: The parameters the drive refused to read this poll (a NAK): unavailable,
    #: not in ``parameters``, and not a failure of the poll.
    unavailable: frozenset[str] = frozenset()


@dataclass(slots=True)
class DriveHealth:
    """What the poller knows of one drive's health.

    ``online`` starts True: a drive is polled in full until ``offline_after``
    failures say otherwise. ``answered`` starts False and turns True at the
    drive's first reply: a drive that has never answered is not online in
    any sense a user means, whatever ``online`` says.
    """

    online: bool = True
    #: True once the drive has replied (anything, a NAK too); False: never heard from.
    answered: bool = False
    consecutive_failures: int = 0
    last_error: str | None = None
    polls: int = 0
    failures: int = 0
    #: Loop time of the last good poll (None before the first).
    last_ok: float | None = None
    #: Loop time before which an offline drive is not probed again.
    next_probe: float = 0.0
    #: The parameters the drive refused at their latest read (see the module docstring).
    unavailable: set[str] = field(default_factory=set)


@dataclass(slots=True)
class BusPollStats:
    """Polling statistics of one bus."""

    cycles: int = 0
    last_cycle_s: float = 0.0
    max_cycle_s: float = 0.0
    total_cycle_s: float = 0.0
    errors: int = 0
    #: Offline probes made (each one attempt of the protocol's cheap request).
    probes: int = 0
    #: Exceptions raised by ``on_sample`` callbacks (logged; polling went on).
    callback_errors: int = 0

    @property
    def mean_cycle_s(self) -> float | None:
        """Mean duration of a polling cycle, None before the first."""
        return self.total_cycle_s / self.cycles if self.cycles else None
