"""A value's OPC UA quality and timestamps, and a refused write's status code.

A drive value's quality is the core's, not ours: the served view
(:class:`~sj300_async.gateway.ServedDrive`) judges each value's
:class:`~sj300_async.gateway.Quality` once for every northbound, and
:data:`QUALITY_STATUS` only words it as OPC UA's status code
(docs/OPCUA.md, "Time and quality"):

=====================  ==============================
the served quality     the status code
=====================  ==============================
``GOOD``               ``Good``
``STALE``              ``UncertainLastUsableValue`` (with the last value)
``OFFLINE``            ``BadNoCommunication``
``NEVER``              ``BadWaitingForInitialData``
``UNAVAILABLE``        ``BadDataUnavailable``
=====================  ==============================

A Bad value carries no value (OPC UA Part 4, 7.7.1). The SourceTimestamp
is the wall-clock time the value was read from the drive (the snapshot's
loop times turned into Unix time through the snapshot's own pair); the
ServerTimestamp is when it is served.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Final

from asyncua import ua

from .. import Quality, Refusal

__all__ = [
    "BAD_DATA_UNAVAILABLE",
    "BAD_NO_COMMUNICATION",
    "BAD_WAITING",
    "GOOD",
    "QUALITY_STATUS",
    "REFUSAL_STATUS",
    "UNCERTAIN_LAST_USABLE",
    "refusal_status",
    "utc",
]

GOOD: Final[int] = ua.StatusCodes.Good
BAD_NO_COMMUNICATION: Final[int] = ua.StatusCodes.BadNoCommunication
BAD_WAITING: Final[int] = ua.StatusCodes.BadWaitingForInitialData
BAD_DATA_UNAVAILABLE: Final[int] = ua.StatusCodes.BadDataUnavailable
UNCERTAIN_LAST_USABLE: Final[int] = ua.StatusCodes.UncertainLastUsableValue

#: The served quality as OPC UA's status code: the one place it is worded.
QUALITY_STATUS: Final[Mapping[Quality, int]] = {
    Quality.GOOD: GOOD,
    Quality.STALE: UNCERTAIN_LAST_USABLE,
    Quality.OFFLINE: BAD_NO_COMMUNICATION,
    Quality.NEVER: BAD_WAITING,
    Quality.UNAVAILABLE: BAD_DATA_UNAVAILABLE,
}


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
