"""Which trip a drive is in, as the commands name it: ``E07 over-voltage``, ``fault H9A``.

A drive's status says only *that* it is tripped; the trip itself is the
newest entry of its history, read and named by the drive's profile
(:meth:`~sj300_async.profiles.Profile.read_latest_trip`).
"""

from __future__ import annotations

from typing import Any

from ..profiles import Profile, Trip
from ..wire import NakError, RemoteProtocolError

__all__ = ["trip_or_none"]


async def trip_or_none(profile: Profile, drive: Any) -> Trip | None:
    """The drive's newest trip, or None when it keeps none, refuses or garbles its history.

    Raises:
        ReplyTimeoutError, TransportError: the drive or the link failed.
    """
    try:
        return await profile.read_latest_trip(drive)
    except (NakError, RemoteProtocolError):
        return None
