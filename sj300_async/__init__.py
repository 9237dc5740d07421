"""sj300_async: an asyncio protocol stack for Hitachi SJ300 (and Mitsubishi FR-700) inverters.

This is the user's API: open a bus, get its drives, poll them, handle the
typed errors. The protocols' codecs live in their own packages
(:mod:`sj300_async.sj300`, :mod:`sj300_async.fr700`), the protocol-neutral
async stack in :mod:`sj300_async.bus`, the transports in
:mod:`sj300_async.transports` and the simulated drives in
:mod:`sj300_async.simulator`. docs/ARCHITECTURE.md shows how they fit.
"""

from __future__ import annotations

from ._open import open_bus
from ._poll_results import BusPollStats, DriveHealth, Sample
from ._poller import Poller
from .bus import Bus, BusStats, BusTiming, ReconnectPolicy
from .fr700 import Fr700Drive, Fr700Monitor, Fr700Status
from .sj300 import (
    Broadcast,
    Drive,
    InputMonitor,
    InputTerminal,
    InverterStatus,
    MonitorData,
    NakCode,
    OutputTerminal,
    StatusA,
    StatusB,
    StatusC,
    TripHistory,
    TripRecord,
    TripStatusB,
    TripStatusC,
)
from .version import __version__
from .wire import (
    BusClosedError,
    Direction,
    LineSettings,
    LocalProtocolError,
    NakError,
    ProtocolError,
    ReadOnlyError,
    RemoteProtocolError,
    ReplyTimeoutError,
    SJ300Error,
    TransportError,
)

__all__ = [
    "Broadcast",
    "Bus",
    "BusClosedError",
    "BusPollStats",
    "BusStats",
    "BusTiming",
    "Direction",
    "Drive",
    "DriveHealth",
    "Fr700Drive",
    "Fr700Monitor",
    "Fr700Status",
    "InputMonitor",
    "InputTerminal",
    "InverterStatus",
    "LineSettings",
    "LocalProtocolError",
    "MonitorData",
    "NakCode",
    "NakError",
    "OutputTerminal",
    "Poller",
    "ProtocolError",
    "ReadOnlyError",
    "ReconnectPolicy",
    "RemoteProtocolError",
    "ReplyTimeoutError",
    "SJ300Error",
    "Sample",
    "StatusA",
    "StatusB",
    "StatusC",
    "TransportError",
    "TripHistory",
    "TripRecord",
    "TripStatusB",
    "TripStatusC",
    "__version__",
    "open_bus",
]
