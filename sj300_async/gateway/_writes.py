"""A write as every northbound hands it to the gateway, and the gateway's neutral answer.

A northbound turns what its client sent (a Modbus register write, an MQTT
``…/set/…`` message, later an HTTP form or an OPC UA method call) into one
of the :data:`WriteRequest` types, and the gateway judges and carries it out
the same way whoever asked (:mod:`._control`). The answer is a
:class:`WriteResult`: done, or refused with a :class:`Refusal` and a
sentence saying why. Each northbound maps a refusal to its own vocabulary
(a Modbus exception code, the MQTT error topic's ``reason``); the audit log
records the neutral reason, so one log reads the same whichever door a
write came through.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from ..wire import Direction

__all__ = [
    "DROPPED_BY_STOP",
    "Heartbeat",
    "ParameterValue",
    "ParameterWrite",
    "Refusal",
    "RunCommand",
    "SetFrequency",
    "WriteRequest",
    "WriteResult",
    "needs_lease",
]


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """Take or renew the drive's control lease."""


@dataclass(frozen=True, slots=True)
class RunCommand:
    """Run forward, run reverse, or stop."""

    direction: Direction


@dataclass(frozen=True, slots=True)
class SetFrequency:
    """Set the output frequency, in Hz."""

    hz: float


@dataclass(frozen=True, slots=True)
class ParameterWrite:
    """Write one parameter: *raw* is the drive's integer (its setting increment counted).

    For a door whose wire carries the integer (Modbus, the HTTP API's ``raw``);
    the gateway refuses one outside the parameter's range.
    """

    code: str
    raw: int


@dataclass(frozen=True, slots=True)
class ParameterValue:
    """Write one parameter: *value* in its unit, as the client sent it (*text*, for the
    refusal's sentence).

    For a door whose wire carries a number in the parameter's unit (MQTT, Sparkplug,
    OPC UA, the HTTP API's ``value``). The gateway makes it the drive's integer, or
    refuses it (outside the range, finer than the setting increment, not a number),
    after the grants and before the drive's state, as it judges every write.
    """

    code: str
    value: float
    text: str = ""


WriteRequest = Heartbeat | RunCommand | SetFrequency | ParameterWrite | ParameterValue


class Refusal(enum.Enum):
    """Why a write was not carried out (the value is the audit log's and MQTT's word)."""

    #: The configuration grants no such write to this drive (or none at all).
    NOT_ALLOWED = "not_allowed"
    #: A command without the drive's control lease.
    NO_LEASE = "no_lease"
    #: Another client holds the drive's control lease.
    LEASE_HELD = "lease_held"
    #: A value the drive must not get (out of range, finer than its step): nothing was sent.
    INVALID_VALUE = "invalid_value"
    #: The request could not be read (not a number, not text): nothing was sent.
    MALFORMED = "malformed"
    #: No such target (no such register, parameter or command).
    UNKNOWN_TARGET = "unknown_target"
    #: Too many requests already wait for this drive.
    BUSY = "busy"
    #: The drive refused it (a NAK).
    DRIVE_REFUSED = "drive_refused"
    #: The drive took it but read back something else.
    NOT_CONFIRMED = "not_confirmed"
    #: The drive did not answer, or the line is down.
    NO_ANSWER = "no_answer"


@dataclass(frozen=True, slots=True)
class WriteResult:
    """What became of a write: done (``refusal`` None), or refused and why."""

    refusal: Refusal | None = None
    #: A sentence for people: why it was refused ("" when done).
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.refusal is None

    def __str__(self) -> str:
        if self.refusal is None:
            return "ok"
        return f"{self.refusal.value}: {self.detail}" if self.detail else self.refusal.value


#: The one result of a write that was done.
DONE = WriteResult()

#: A command still waiting for its drive when a stop for it came: never carried out
#: (a stop waits behind no command). Every door that queues commands per drive
#: (the MQTT JSON topics, Sparkplug) answers the dropped one with it.
DROPPED_BY_STOP: Final = WriteResult(Refusal.BUSY, "dropped: a stop came after it")


def needs_lease(request: WriteRequest) -> bool:
    """Run and frequency commands need the control lease (a stop and a parameter write do
    not: a stop is the safe direction, a parameter no motion)."""
    if isinstance(request, RunCommand):
        return request.direction != Direction.STOP
    return isinstance(request, SetFrequency)
