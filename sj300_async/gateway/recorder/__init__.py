"""The trip black box: each drive's seconds around every trip, kept as a record.

:mod:`._settings` reads ``[recorder]``; :mod:`._recorder` sees trips in the
gateway's samples and makes the records; :mod:`._record` is a record's
JSON; :mod:`._samples_csv` its CSV, made in a child by :mod:`._csv_process`;
:mod:`._store` keeps them (a directory, or memory). The doors serve what
the store holds: they never judge what a trip is.
docs/guide/trips.md is the user's guide.
"""

from __future__ import annotations

from ._csv_process import CsvFailed, record_csv
from ._record import record_id, trip_fields
from ._recorder import TripRecorder
from ._samples_csv import samples_csv
from ._settings import RECORDER_KEYS, RecorderConfig
from ._store import FORMAT, RECORD_ID, RecordSummary, TripStore

__all__ = [
    "FORMAT",
    "RECORDER_KEYS",
    "RECORD_ID",
    "CsvFailed",
    "RecordSummary",
    "RecorderConfig",
    "TripRecorder",
    "TripStore",
    "record_csv",
    "record_id",
    "samples_csv",
    "trip_fields",
]
