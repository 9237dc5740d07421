"""The trip records' routes: the list, a record, its frames, its samples as CSV.

``GET /api/v1/trips`` lists the records kept, newest first (``line``,
``node`` and ``limit`` narrow it); ``GET /api/v1/trips/ID`` is a record
whole, with its ``samples``; ``/api/v1/trips/ID/frames.pcapng`` its line's
frames; ``/api/v1/trips/ID.csv`` its samples. What a trip is and what a
record holds is the core's (:mod:`sj300_async.gateway.recorder`): these
routes read its store and answer.

Decisions:

- They read, as the rest of the API's GETs: no login. A gateway with the
  recorder off answers the list empty with ``"recording": false`` and 404
  for a record.
- An id that is not a record id's shape is 404 without a look at the
  disk; a record whose file went missing or does not read (a disk that
  failed since the start) is 404 too, its cause logged by the store.
- A record's file is read in a thread, and its CSV made in a child
  process (:func:`~sj300_async.gateway.recorder.record_csv`: a big
  record's parse would hold the GIL): at most :data:`READERS` at once,
  whoever asks, so that a client asking for records in a loop costs the
  loop nothing and the disk a few reads. A CSV the child could not make
  is 503, said in the log.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Final

from aiohttp import web

from .. import GatewayView
from ..recorder import RECORD_ID, CsvFailed, TripStore, record_csv
from ._replies import json_error, json_reply

__all__ = ["READERS", "TripRoutes"]

_log = logging.getLogger(__name__)

#: Record files read (or turned into CSV) at once, at most.
READERS: Final = 4
#: The most summaries one list answers.
MAX_LIMIT: Final = 1000


class TripRoutes:
    """The trip records' routes of one gateway's workbench (see the module docstring)."""

    def __init__(self, gateway: GatewayView) -> None:
        self.gateway = gateway
        self._readers = asyncio.Semaphore(READERS)

    def add_to(self, app: web.Application) -> None:
        app.router.add_get("/api/v1/trips", self._list)
        app.router.add_get(r"/api/v1/trips/{id:[^/]+}.csv", self._csv)
        app.router.add_get("/api/v1/trips/{id}/frames.pcapng", self._frames)
        app.router.add_get("/api/v1/trips/{id}", self._record)

    async def _list(self, request: web.Request) -> web.Response:
        store = self.gateway.trip_records
        line = request.query.get("line")
        node = _number(request, "node", 0, 999, None)
        limit = _number(request, "limit", 1, MAX_LIMIT, MAX_LIMIT)
        assert limit is not None
        found = [] if store is None else store.summaries(line, node)[:limit]
        return json_reply({"recording": store is not None, "trips": [s.as_json() for s in found]})

    async def _record(self, request: web.Request) -> web.Response:
        store, record_id = self._store(request)
        async with self._readers:
            data = await store.read(record_id)
        if data is None:
            raise _missing(record_id)
        return web.Response(body=data, content_type="application/json")

    async def _frames(self, request: web.Request) -> web.Response:
        store, record_id = self._store(request)
        async with self._readers:
            data = await store.frames(record_id)
        if data is None:
            raise _missing(record_id)
        return web.Response(
            body=data,
            content_type="application/vnd.tcpdump.pcap",
            headers={"Content-Disposition": f'attachment; filename="{record_id}.pcapng"'},
        )

    async def _csv(self, request: web.Request) -> web.Response:
        store, record_id = self._store(request)
        async with self._readers:
            data = await store.read(record_id)
            if data is None:
                raise _missing(record_id)
            try:
                csv = await record_csv(data)
            except ValueError as exc:  # a file changed since the start (another JSON, a
                # time no date holds): not a record now
                raise json_error(404, f"trip record {record_id!r} does not read: {exc}") from None
            except CsvFailed as exc:
                _log.warning("trip record %s: %s", record_id, exc)
                raise json_error(503, f"trip record {record_id!r}: {exc}") from None
        return web.Response(
            body=csv,
            content_type="text/csv",
            charset="utf-8",
            headers={"Content-Disposition": f'attachment; filename="{record_id}.csv"'},
        )

    def _store(self, request: web.Request) -> tuple[TripStore, str]:
        record_id = request.match_info["id"]
        store = self.gateway.trip_records
        if store is None or not RECORD_ID.fullmatch(record_id):
            raise _missing(record_id)
        return store, record_id


def _missing(record_id: str) -> web.HTTPException:
    return json_error(404, f"no trip record {record_id[:80]!r}")


def _number(request: web.Request, key: str, low: int, high: int, default: int | None) -> int | None:
    text = request.query.get(key)
    if text is None:
        return default
    # Digits only, leading zeros dropped, no longer than the bound: what is checked is
    # what is used (int() of 5,000 digits raises, and "0001000" is 1000).
    digits = text.lstrip("0") or "0" if text.isascii() and text.isdigit() else ""
    if not digits or len(digits) > len(str(high)) or not low <= int(digits) <= high:
        raise json_error(400, f"{key}: expected {low}..{high}, got {text[:32]!r}")
    return int(digits)
