"""The protocol-neutral drive model and the profile interface every protocol implements.

One frozen :class:`DriveSnapshot` per drive sample is what the gateway's
northbounds and the command line read; a protocol's :class:`Profile` says
what its drives' answers mean (status, monitor, trips, parameters, the
register block) and what they can do. :func:`get_profile` finds a
protocol's profile through its dialect. docs/ARCHITECTURE.md, "The drive
model and the profiles", shows where this sits.
"""

from __future__ import annotations

from ._backup import (
    BACKUP_FORMAT,
    BACKUP_VERSION,
    BackupFormatError,
    ParameterBackup,
    catalogued,
    parameter_code,
    utc_now,
)
from ._build import build_snapshot
from ._profile import (
    Capabilities,
    ParameterCatalogue,
    ParameterSpec,
    Profile,
    RegisterField,
    RegisterLayout,
    in_counts,
)
from ._readings import DriveReadings, PollResult, raw_value
from ._registry import get_profile, profiled_protocols
from ._snapshot import (
    NEVER,
    DriveSnapshot,
    MonitorView,
    ParameterReading,
    ReadGroup,
    StatusView,
    Trip,
    TripLog,
    is_fresh,
    read_time,
)
from ._words import frame_text, words

__all__ = [
    "BACKUP_FORMAT",
    "BACKUP_VERSION",
    "NEVER",
    "BackupFormatError",
    "Capabilities",
    "DriveReadings",
    "DriveSnapshot",
    "MonitorView",
    "ParameterBackup",
    "ParameterCatalogue",
    "ParameterReading",
    "ParameterSpec",
    "PollResult",
    "Profile",
    "ReadGroup",
    "RegisterField",
    "RegisterLayout",
    "StatusView",
    "Trip",
    "TripLog",
    "build_snapshot",
    "catalogued",
    "frame_text",
    "get_profile",
    "in_counts",
    "is_fresh",
    "parameter_code",
    "profiled_protocols",
    "raw_value",
    "read_time",
    "utc_now",
    "words",
]
