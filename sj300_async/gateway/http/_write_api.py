"""The workbench's routes that write: log in and out, and control a drive under its lease.

Registered only when the gateway grants some write and ``[http]`` names
someone who may write (:mod:`._auth`); otherwise these paths do not
exist (404), and every path refuses other methods than GET (405): a
read-only gateway has no write endpoint at all, not merely hidden buttons.

Every write goes through :meth:`~sj300_async.gateway.GatewayView.write`,
the door every northbound uses: the same grants, the same control lease
(a run or a set frequency needs it; a stop does not: stop is the safe
direction, open to anyone allowed to control the drive), the same
validation before anything reaches the wire, the same audit log.

Decisions:

- **Who.** A page's writes name the user and the page (``http:alice#k3f9``:
  the tab's own id): the lease belongs to that tab, so a second tab of the
  same user does not keep it alive, and closing the tab lapses it after
  ``lease_s``. A script's writes name its token (``http-token:NAME``).
- **How the answer reads.** A refusal is ``{"error": sentence, "refusal":
  reason}`` with a status that says what kind of refusal it is
  (:data:`REFUSAL_STATUS`): 403 not allowed, 409 the lease (none, or
  another's), 422 an invalid value, 400 a malformed body, 404 an unknown
  target, 503 busy, 502 the drive refused or did not confirm, 504 no
  answer.
- **Bad input** (not JSON, a body over 64 KiB or nested deeper than
  :mod:`._bodies` reads, a missing or mistyped field) is refused before
  the gateway is asked, and audited through
  :meth:`~sj300_async.gateway.GatewayView.refused` like every refusal.
  A write's body is read only once its credentials are known good.
- **A login costs the loop nothing**: its address's budget is spent
  before the body is read (:mod:`._guards`: 429 with ``Retry-After``
  past it), and the password is checked in the gateway's
  :class:`~sj300_async.gateway.PasswordChecks` thread, off the loop
  (scrypt takes about 65 ms of a core). When too many checks wait
  already, the login is refused unchecked: 503 ``busy``, counted.
"""

from __future__ import annotations

import re
from collections.abc import Awaitable, Callable
from typing import Any, Final

from aiohttp import web

from ...wire import Direction
from .. import (
    DIRECTION_WORDS,
    GatewayDrive,
    GatewayView,
    Heartbeat,
    KeyedBudget,
    ParameterValue,
    ParameterWrite,
    PasswordChecks,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
    excerpt,
)
from ._auth import FAILURE_WINDOW_S, ApiToken, Identity, LoginGuard, Sessions, User, verify_token
from ._bodies import read_json_object
from ._guards import LOGIN_BURST, LOGIN_PER_S, client_address, spend, too_many
from ._replies import find_drive, json_error, json_reply

__all__ = ["MAX_BODY_BYTES", "REFUSAL_STATUS", "SESSION_COOKIE", "WriteRoutes"]

#: The cookie that carries a page's session id.
SESSION_COOKIE: Final = "sj300_session"
#: The header that carries a session's CSRF token.
CSRF_HEADER: Final = "X-CSRF-Token"
#: The largest body of a login or a write.
MAX_BODY_BYTES: Final = 64 * 1024
#: Each refusal's HTTP status (module docstring).
REFUSAL_STATUS: Final = {
    Refusal.NOT_ALLOWED: 403,
    Refusal.NO_LEASE: 409,
    Refusal.LEASE_HELD: 409,
    Refusal.INVALID_VALUE: 422,
    Refusal.MALFORMED: 400,
    Refusal.UNKNOWN_TARGET: 404,
    Refusal.BUSY: 503,
    Refusal.DRIVE_REFUSED: 502,
    Refusal.NOT_CONFIRMED: 502,
    Refusal.NO_ANSWER: 504,
}
_TAB: Final = re.compile(r"[A-Za-z0-9]{1,16}\Z")
#: A run's directions, in the gateway's words (a stop is a call of its own).
_DIRECTIONS: Final = {DIRECTION_WORDS[d]: d for d in (Direction.FORWARD, Direction.REVERSE)}

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


class WriteRoutes:
    """The write routes of one gateway's workbench (see the module docstring)."""

    def __init__(
        self,
        gateway: GatewayView,
        users: tuple[User, ...],
        tokens: tuple[ApiToken, ...],
        *,
        secure_cookie: bool,
    ) -> None:
        self.gateway = gateway
        self._users = {user.name: user for user in users}
        self._tokens = tokens
        self._secure = secure_cookie
        self.sessions = Sessions()
        self.guard = LoginGuard()
        #: Each address's budget of password checks (module _guards), and the checks.
        self.budget = KeyedBudget(LOGIN_BURST, LOGIN_PER_S)
        self.checks = PasswordChecks()

    def set_credentials(self, users: tuple[User, ...], tokens: tuple[ApiToken, ...]) -> None:
        """Who may write from the next request (a reload): the sessions of a user no
        longer named, or whose password hash changed, end now."""
        before = self._users
        self._users = {user.name: user for user in users}
        self._tokens = tokens
        gone = {
            name for name, user in before.items()
            if self._users.get(name, None) is None
            or self._users[name].password_hash != user.password_hash
        }  # fmt: skip
        self.sessions.end_users(gone)

    def close(self) -> None:
        """Stop the password checks' thread (a check under way finishes in it)."""
        self.checks.close()

    def add_to(self, app: web.Application) -> None:
        router = app.router
        router.add_post("/api/v1/login", self._login)
        router.add_post("/api/v1/logout", self._logout)
        router.add_get("/api/v1/session", self._session)
        router.add_post("/api/v1/drives/{line}/{node}/lease", self._lease)
        router.add_post("/api/v1/drives/{line}/{node}/run", self._run)
        router.add_post("/api/v1/drives/{line}/{node}/stop", self._stop)
        router.add_post("/api/v1/drives/{line}/{node}/frequency", self._frequency)
        router.add_post("/api/v1/drives/{line}/{node}/parameter", self._parameter)

    # -- who is asking -----------------------------------------------------------------

    def identify(self, request: web.Request) -> Identity | None:
        """The identity of *request*'s credentials (a token, else a session), or None."""
        header = request.headers.get("Authorization", "")
        if header:
            scheme, _, token = header.partition(" ")
            if scheme.lower() != "bearer" or not token:
                return None
            for known in self._tokens:
                if verify_token(token.strip(), known.token_hash):
                    return Identity(known.name, "token")
            return None
        session = self.sessions.get(request.cookies.get(SESSION_COOKIE))
        if session is None:
            return None
        return Identity(session.user, "user", session.id)

    def writer(self, request: web.Request) -> Identity:
        """The identity allowed to write *request*, or the refusal (401, 403) raised."""
        _same_origin(request)
        identity = self.identify(request)
        if identity is None:
            raise json_error(401, "log in first (or send Authorization: Bearer TOKEN)")
        if identity.kind == "user":
            session = self.sessions.get(identity.session)
            sent = request.headers.get(CSRF_HEADER, "")
            if session is None or not sent or sent != session.csrf:
                raise json_error(403, f"missing or wrong {CSRF_HEADER}: reload the page")
        return identity

    # -- sessions ----------------------------------------------------------------------

    async def _login(self, request: web.Request) -> web.Response:
        _same_origin(request)
        address = client_address(request)
        if self.guard.blocked(address):
            raise too_many(
                "too many failed logins from this address: wait 5 minutes", FAILURE_WINDOW_S
            )
        spend(self.budget, address, "logins")  # before the body is read (module docstring)
        body = await read_json_object(request, MAX_BODY_BYTES)
        name, password = body.get("name"), body.get("password")
        if not isinstance(name, str) or not isinstance(password, str):
            raise json_error(400, 'expected {"name": ..., "password": ...}')
        user = self._users.get(name)
        # The hash is computed for an unknown name too: the time does not tell names apart.
        stored = user.password_hash if user is not None else _DUMMY_HASH
        verdict = await self.checks.verify(password, stored)
        if verdict is None:
            error = json_error(503, "busy: too many logins being checked", refusal="busy")
            error.headers["Retry-After"] = "1"
            raise error
        if not verdict or user is None:
            self.guard.failed(address)
            raise json_error(401, "unknown user or wrong password")
        self.guard.succeeded(address)
        self.budget.refund(address)  # a login that succeeds costs its address nothing
        session = self.sessions.create(user.name)
        response = json_reply({"user": user.name, "csrf": session.csrf})
        response.set_cookie(
            SESSION_COOKIE,
            session.id,
            httponly=True,
            samesite="Strict",
            secure=self._secure,
            path="/",
        )
        return response

    async def _logout(self, request: web.Request) -> web.Response:
        identity = self.writer(request)
        self.sessions.end(identity.session)
        response = json_reply({"user": None})
        response.del_cookie(SESSION_COOKIE, path="/")
        return response

    async def _session(self, request: web.Request) -> web.Response:
        """Who the page is logged in as, with its CSRF token; nulls when it is not.

        Not logged in is an answer, not an error: the page asks at every load.
        """
        session = self.sessions.get(request.cookies.get(SESSION_COOKIE))
        if session is None:
            return json_reply({"user": None, "csrf": None})
        return json_reply({"user": session.user, "csrf": session.csrf})

    # -- control -----------------------------------------------------------------------

    async def _lease(self, request: web.Request) -> web.Response:
        return await self._write(request, lambda body: Heartbeat())

    async def _stop(self, request: web.Request) -> web.Response:
        return await self._write(request, lambda body: RunCommand(Direction.STOP))

    async def _run(self, request: web.Request) -> web.Response:
        def command(body: dict[str, Any]) -> WriteRequest:
            direction = _DIRECTIONS.get(body.get("direction", "forward"))
            if direction is None:
                raise _BadBody('direction: expected "forward" or "reverse"')
            return RunCommand(direction)

        return await self._write(request, command)

    async def _frequency(self, request: web.Request) -> web.Response:
        def command(body: dict[str, Any]) -> WriteRequest:
            hz = body.get("hz")
            # NaN and infinities are numbers the gateway refuses (invalid_value, after the
            # grants), as from every door (issue 42); Python's JSON reads NaN and Infinity.
            if isinstance(hz, bool) or not isinstance(hz, int | float):
                raise _BadBody("hz: expected a number of hertz")
            return SetFrequency(float(hz))

        return await self._write(request, command)

    async def _parameter(self, request: web.Request) -> web.Response:
        drive = find_drive(self.gateway, request)

        def command(body: dict[str, Any]) -> WriteRequest:
            text, raw, value = body.get("code"), body.get("raw"), body.get("value")
            if not isinstance(text, str):
                raise _BadBody("code: expected a parameter code")
            catalogue = drive.profile.parameters
            code = catalogue.code(text)
            if code is None:
                raise _BadBody(f"code: {excerpt(text)} is not a parameter code")
            if value is not None:  # in the parameter's unit: the gateway judges it
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise _BadBody("value: expected a number in the parameter's unit")
                return ParameterValue(code, float(value), repr(value))
            if isinstance(raw, bool) or not isinstance(raw, int):
                raise _BadBody("raw: expected the drive's integer (or value: in its unit)")
            return ParameterWrite(code, raw)

        return await self._write(request, command)

    async def _write(
        self, request: web.Request, command: Callable[[dict[str, Any]], WriteRequest]
    ) -> web.Response:
        identity = self.writer(request)
        drive = find_drive(self.gateway, request)
        body = await read_json_object(request, MAX_BODY_BYTES)
        client = identity.client
        tab = body.get("tab")
        if identity.kind == "user":
            if not isinstance(tab, str) or not _TAB.match(tab):
                return self._refuse(client, drive, request, "tab: expected the page's id")
            client = f"{client}#{tab}"
        try:
            write = command(body)
        except _BadBody as bad:
            return self._refuse(client, drive, request, str(bad))
        result = await self.gateway.write(client, drive, write)
        return _answer(result, client, drive)

    def _refuse(
        self,
        client: str,
        drive: GatewayDrive,
        request: web.Request,
        why: str,
        refusal: Refusal = Refusal.MALFORMED,
    ) -> web.Response:
        result = WriteResult(refusal, why)
        self.gateway.refused(client, drive, request.path.rsplit("/", 1)[-1], None, result)
        return _answer(result, client, drive)


class _BadBody(Exception):
    """A field of the body is missing or mistyped."""


#: A valid hash of nothing anyone types: an unknown name costs a real verification.
_DUMMY_HASH: Final = (
    "scrypt$16384$8$1$AAAAAAAAAAAAAAAAAAAAAA==$AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA="
)


def _answer(result: WriteResult, client: str, drive: GatewayDrive) -> web.Response:
    lease = drive.lease
    if result.refusal is None:
        return json_reply({"ok": True, "client": client, "lease_s": lease.duration_s})
    return json_reply(
        {"error": result.detail or result.refusal.value, "refusal": result.refusal.value},
        REFUSAL_STATUS[result.refusal],
    )


def _same_origin(request: web.Request) -> None:
    """Refuse (403) a request a page of another site made the browser send (CSRF)."""
    origin = request.headers.get("Origin")
    if origin is not None and origin != f"{request.scheme}://{request.host}":
        raise json_error(403, f"a request from another site ({excerpt(origin)}) is refused")
    if request.headers.get("Sec-Fetch-Site") == "cross-site":
        raise json_error(403, "a request from another site is refused")
