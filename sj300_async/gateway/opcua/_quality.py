"""A value's OPC UA quality and timestamps, and a refused write's status code.

Quality (docs/OPCUA.md, "Time and quality"), in this order:

1. the drive is offline (the poller's verdict): ``BadNoCommunication``;
2. the value was never read: ``BadWaitingForInitialData``;
3. its read succeeded but the drive does not give it (a trip slot left
   empty, a parameter the drive refused): ``BadDataUnavailable``;
4. it was read longer than ``stale_after_s`` ago: ``UncertainLastUsableValue``
   with the last value;
5. otherwise ``Good``.

A Bad value carries no value (OPC UA Part 4, 7.7.1). The SourceTimestamp
is the wall-clock time the value was read from the drive (the snapshot's
loop times turned into Unix time through the snapshot's own pair); the
ServerTimestamp is when it is served.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Final

from asyncua import ua

from .. import Refusal

__all__ = [
    "BAD_DATA_UNAVAILABLE",
    "BAD_NO_COMMUNICATION",
    "BAD_WAITING",
    "GOOD",
    "REFUSAL_STATUS",
    "UNCERTAIN_LAST_USABLE",
    "quality",
    "refusal_status",
    "utc",
]

GOOD: Final[int] = ua.StatusCodes.Good
BAD_NO_COMMUNICATION: Final[int] = ua.StatusCodes.BadNoCommunication
BAD_WAITING: Final[int] = ua.StatusCodes.BadWaitingForInitialData
BAD_DATA_UNAVAILABLE: Final[int] = ua.StatusCodes.BadDataUnavailable
UNCERTAIN_LAST_USABLE: Final[int] = ua.StatusCodes.UncertainLastUsableValue


def quality(online: bool, at: float, value: object, now: float, stale_after_s: float) -> int:
    """The status code of a value read at loop time *at* (see the module docstring)."""
    if not online:
        return BAD_NO_COMMUNICATION
    if at == -math.inf:
        return BAD_WAITING
    if value is None:
        return BAD_DATA_UNAVAILABLE
    if now - at > stale_after_s:
        return UNCERTAIN_LAST_USABLE
    return GOOD


def utc(unix: float) -> datetime:
    """Unix time as the aware datetime asyncua encodes."""
    return datetime.fromtimestamp(unix, UTC)


#: A gateway refusal as the status code of the call or write (docs/OPCUA.md, "Refusals").
REFUSAL_STATUS: Final = {
    Refusal.NOT_ALLOWED: ua.StatusCodes.BadUserAccessDenied,
    Refusal.NO_LEASE: ua.StatusCodes.BadInvalidState,
    Refusal.LEASE_HELD: ua.StatusCodes.BadLocked,
    Refusal.INVALID_VALUE: ua.StatusCodes.BadOutOfRange,
    Refusal.MALFORMED: ua.StatusCodes.BadInvalidArgument,
    Refusal.UNKNOWN_TARGET: ua.StatusCodes.BadNodeIdUnknown,
    Refusal.BUSY: ua.StatusCodes.BadResourceUnavailable,
    Refusal.DRIVE_REFUSED: ua.StatusCodes.BadDeviceFailure,
    Refusal.NOT_CONFIRMED: ua.StatusCodes.BadDeviceFailure,
    Refusal.NO_ANSWER: ua.StatusCodes.BadNoCommunication,
}


def refusal_status(refusal: Refusal | None) -> int:
    """The status code of a write's result (Good when done)."""
    return GOOD if refusal is None else int(REFUSAL_STATUS[refusal])
