"""The workbench's parameter list: read a drive's whole set with progress, check a backup file.

``GET /api/v1/drives/LINE/NODE/parameters`` reads every code a drive of
the protocol can have (the profile's
:meth:`~sj300_async.profiles.ParameterCatalogue.addressable`: SJ300's 335
function codes, FR-700's Pr.0..Pr.999) and streams it as server-sent
events: ``progress`` after each read, then ``backup``, the whole set in
the ``sj300 params`` file format (:class:`~sj300_async.profiles.ParameterBackup`),
which the page shows, compares and offers as a download.
``POST /api/v1/parameters/check`` reads a backup file (an upload) with the
same reader ``sj300 params restore`` uses and answers its parameters, or
400 with the reason: it changes nothing, and exists on a read-only gateway.

Decisions:

- **The line first.** The reads queue on the line's arbiter like every
  request, between the polls; a whole set is hundreds of transactions, so
  one line runs at most one at a time (409 for a second), and a client
  that goes away stops it (the next progress event's write fails).
- A code the drive refuses as not its own (the profile's
  :meth:`~sj300_async.profiles.Profile.absent` NAK) is recorded absent, as
  a backup records it; any other failure ends the stream with an ``error``
  event naming the code, after the codes read so far.
- The stream carries no CSRF token and needs no login: it reads. It
  counts against its address's streams (:mod:`._guards`), and a client
  that closes it, the documented way to stop it, is a DEBUG line.
- A backup file to check is read whole (at most :data:`MAX_BACKUP_BYTES`,
  within the request's time), its nesting and its number of arrays and
  objects (:data:`MAX_BACKUP_CONTAINERS`) checked before it is parsed
  (:mod:`._bodies`), and each address has a budget of checks
  (:mod:`._guards`), spent before the body is read.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Final

from aiohttp import web

from ...profiles import BackupFormatError, ParameterBackup, catalogued, utc_now
from ...wire import LocalProtocolError, NakError, SJ300Error
from .. import GatewayDrive, GatewayView
from ._bodies import MAX_DEPTH, read_body, shape_problem
from ._events import sse_frame
from ._guards import PerAddress, client_address, spend
from ._replies import find_drive, json_error, json_reply

__all__ = ["MAX_BACKUP_BYTES", "MAX_BACKUP_CONTAINERS", "ParameterRoutes"]

_log = logging.getLogger("sj300_async.gateway.http")

#: The largest backup file accepted (an FR-700 one is about 165 kB).
MAX_BACKUP_BYTES: Final = 1024 * 1024
#: The arrays and objects a backup file may hold (a whole FR-700 set: 1,002).
MAX_BACKUP_CONTAINERS: Final = 4096


class ParameterRoutes:
    """The parameter routes of one gateway's workbench (see the module docstring)."""

    def __init__(self, gateway: GatewayView, per_address: PerAddress) -> None:
        self.gateway = gateway
        #: Each address's open streams (shared with the event stream's route) and
        #: budget of backup checks.
        self.per_address = per_address
        #: Lines reading a whole set now.
        self._busy: set[str] = set()

    def add_to(self, app: web.Application) -> None:
        app.router.add_get("/api/v1/drives/{line}/{node}/parameters", self._read)
        app.router.add_post("/api/v1/parameters/check", self._check)
        app.router.add_get("/api/v1/drives/{line}/{node}/defaults", self._defaults)

    async def _read(self, request: web.Request) -> web.StreamResponse:
        drive = find_drive(self.gateway, request)
        profile = drive.profile
        name = drive.line.name
        if not profile.capabilities.parameter_backup:
            raise json_error(
                404, f"{profile.model} drives (protocol {profile.name}) have no parameter backup"
            )
        if name in self._busy:
            raise json_error(
                409, f"line {name} is reading a drive's parameters already: wait for it"
            )
        address = client_address(request)
        streams = self.per_address.streams
        streams.acquire(address)
        try:
            return await self._read_set(request, name, drive)
        finally:
            streams.release(address)

    async def _read_set(
        self, request: web.Request, name: str, drive: GatewayDrive
    ) -> web.StreamResponse:
        profile = drive.profile
        line = next(line for line in self.gateway.lines if line.config.name == name)
        codes = list(profile.parameters.addressable())
        response = web.StreamResponse(
            headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"}
        )
        self._busy.add(name)
        raw: dict[str, int] = {}
        absent: dict[str, str] = {}
        try:
            await response.prepare(request)
            for done, code in enumerate(codes, start=1):
                try:
                    raw[code] = await self.gateway.read_parameter_raw(drive, code)
                except NakError as exc:
                    if not profile.absent(int(exc.code)):
                        raise
                    absent[code] = str(exc).partition(" answered ")[2] or f"NAK {int(exc.code)}"
                await response.write(
                    sse_frame("progress", {"done": done, "total": len(codes), "code": code})
                )
            backup = ParameterBackup(
                drive.node,
                line.config.url,
                raw,
                absent,
                utc_now(),
                profile.name,
            )
            await response.write(sse_frame("backup", backup.to_json(profile)))
        except SJ300Error as exc:
            message = f"{code}: {exc}" if codes else str(exc)
            _log.info("line %s node %d: parameter read stopped: %s", name, drive.node, message)
            await response.write(sse_frame("error", {"error": message, "done": len(raw)}))
        except ConnectionError:
            # The client closed the stream: the documented way to stop it, not an error.
            _log.debug("line %s node %d: parameter read stopped by its client", name, drive.node)
            return response
        except asyncio.CancelledError:
            _log.debug("line %s node %d: parameter read cancelled", name, drive.node)
            raise
        finally:
            self._busy.discard(name)
        await response.write_eof()
        return response

    async def _defaults(self, request: web.Request) -> web.Response:
        """The factory settings the catalogue knows for this drive's protocol, as a check's
        answer reads (the page compares with them as with a file)."""
        profile = find_drive(self.gateway, request).profile
        catalogue = profile.parameters
        known: dict[str, dict[str, float | int]] = {}
        for code in catalogue.addressable():
            spec = catalogued(profile, code)
            if spec is None or spec.default is None:
                continue
            try:
                known[code] = {"raw": spec.to_raw(spec.default), "value": spec.default}
            except LocalProtocolError:  # a default outside the catalogue's own range
                _log.debug("%s: default %r is not a valid setting", code, spec.default)
        return json_reply(
            {"protocol": profile.name, "parameters": known, "absent": {}, "partial": True}
        )

    async def _check(self, request: web.Request) -> web.Response:
        """A backup file's parameters as this gateway reads them, or why it cannot."""
        protocol = request.query.get("protocol", "")
        profile = next(
            (line.profile for line in self.gateway.lines if line.config.protocol == protocol),
            None,
        )
        if profile is None:
            raise json_error(
                400, f"protocol: none of this gateway's lines speaks {protocol[:32]!r}"
            )
        spend(self.per_address.checks, client_address(request), "backup checks")
        # The application's 64 KiB body limit is for requests, not backups.
        data = await read_body(request, MAX_BACKUP_BYTES, "a backup")
        problem = shape_problem(data, MAX_DEPTH, MAX_BACKUP_CONTAINERS)
        if problem is not None:  # before the parser (module _bodies)
            raise json_error(400, f"the file: not JSON the gateway reads: {problem}")
        try:
            backup = ParameterBackup.from_bytes(data, profile, source="the file")
        except BackupFormatError as exc:
            raise json_error(400, str(exc)) from None
        except RecursionError:  # the check above makes it impossible: a last guard
            raise json_error(400, "the file: not JSON the gateway reads: too deep") from None
        return json_reply(
            {
                "node": backup.node,
                "protocol": backup.protocol,
                "taken_at": backup.taken_at,
                "parameters": {
                    code: {
                        "raw": raw,
                        "value": None
                        if (spec := catalogued(profile, code)) is None
                        else spec.from_raw(raw),
                    }
                    for code, raw in backup.parameters.items()
                },
                "absent": dict(backup.absent),
            }
        )
