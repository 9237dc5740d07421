"""Who may write through the workbench: users with hashed passwords, API tokens, sessions, CSRF.

Sans-IO but for the clock. The HTTP northbound serves its write routes
only when the configuration names someone who may use them
(``[[http.users]]`` or ``[[http.tokens]]``) and some line grants writes;
every write then needs one of:

- **a session** (the page): ``POST /api/v1/login`` with a user's name and
  password gives a random session id in a cookie (``HttpOnly``,
  ``SameSite=Strict``, ``Secure`` over TLS) and a CSRF token the page
  sends back in ``X-CSRF-Token`` with every write. A write with the
  cookie and without the matching token, or from another origin (its
  ``Origin`` header names another site), is refused: a page elsewhere
  cannot make the operator's browser write (CSRF).
- **a token** (a script): ``Authorization: Bearer TOKEN``. A browser
  never sends it by itself, so it needs no CSRF token.

Decisions:

- Passwords are stored as scrypt hashes, made and checked by the
  gateway's core (``gateway/_passwords.py``, shared with OPC UA). Tokens are random and
  long (32 bytes), so a plain SHA-256 of one is enough; ``sj300 gateway
  --new-token`` makes a token and its hash. Both are compared in
  constant time.
- Sessions live in memory (a restart logs everyone out), end after
  :data:`SESSION_S` without use or at logout, and are at most
  :data:`MAX_SESSIONS` (the oldest goes first).
- Failed logins are counted per client address: after
  :data:`MAX_FAILURES` within :data:`FAILURE_WINDOW_S`, that address is
  refused for the rest of the window (429), whatever it sends.
- Reading needs no login: the plant network sees the drives as it sees
  Modbus and /metrics. Only writes are guarded.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from typing import Final

from .. import User, hash_password, verify_password

__all__ = [
    "FAILURE_WINDOW_S",
    "MAX_FAILURES",
    "MAX_SESSIONS",
    "SESSION_S",
    "ApiToken",
    "Identity",
    "LoginGuard",
    "Session",
    "Sessions",
    "User",
    "hash_password",
    "hash_token",
    "new_token",
    "verify_password",
    "verify_token",
]

#: Seconds a session lasts without use.
SESSION_S: Final = 8 * 3600.0
#: Sessions kept at most (the least recently used ends first).
MAX_SESSIONS: Final = 256
#: Failed logins from one address within the window before it is refused.
MAX_FAILURES: Final = 10
FAILURE_WINDOW_S: Final = 300.0


def new_token() -> str:
    """A random API token (32 bytes, URL-safe text)."""
    return secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    """``sha256$HEX``: what ``token_hash`` holds."""
    return "sha256$" + hashlib.sha256(token.encode("utf-8")).hexdigest()


def verify_token(token: str, stored: str) -> bool:
    return hmac.compare_digest(hash_token(token), stored)


@dataclass(frozen=True, slots=True)
class ApiToken:
    """``[[http.tokens]]``: a script that may write with ``Authorization: Bearer``."""

    name: str
    token_hash: str


@dataclass(frozen=True, slots=True)
class Identity:
    """Who is writing: a user through a session, or a token's name."""

    name: str
    #: ``"user"`` or ``"token"``.
    kind: str
    #: The session's id (a user), for the audit log's client name.
    session: str | None = None

    @property
    def client(self) -> str:
        """The client name the audit log and the lease know it by."""
        return f"http:{self.name}" if self.kind == "user" else f"http-token:{self.name}"


@dataclass(slots=True)
class Session:
    id: str
    user: str
    csrf: str
    expires: float


@dataclass(slots=True)
class Sessions:
    """The logged-in sessions (see the module docstring)."""

    clock: Callable[[], float] = time.monotonic
    _sessions: dict[str, Session] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self._sessions)

    def create(self, user: str) -> Session:
        while len(self._sessions) >= MAX_SESSIONS:
            del self._sessions[next(iter(self._sessions))]  # the least recently used
        session = Session(
            secrets.token_urlsafe(32), user, secrets.token_urlsafe(32), self.clock() + SESSION_S
        )
        self._sessions[session.id] = session
        return session

    def get(self, session_id: str | None) -> Session | None:
        """The live session *session_id* names (its time renewed), or None."""
        if not session_id:
            return None
        session = self._sessions.get(session_id)
        if session is None:
            return None
        now = self.clock()
        if now > session.expires:
            del self._sessions[session_id]
            return None
        session.expires = now + SESSION_S
        self._sessions[session_id] = self._sessions.pop(session_id)  # most recently used last
        return session

    def end(self, session_id: str | None) -> None:
        if session_id:
            self._sessions.pop(session_id, None)

    def end_users(self, users: Collection[str]) -> None:
        """End every session of *users* (removed, or their password changed)."""
        for session_id, session in list(self._sessions.items()):
            if session.user in users:
                del self._sessions[session_id]


@dataclass(slots=True)
class LoginGuard:
    """Failed logins per client address (see the module docstring)."""

    clock: Callable[[], float] = time.monotonic
    _failures: dict[str, list[float]] = field(default_factory=dict)
    #: Logins refused for too many failures, since the start.
    refused: int = 0

    def _recent(self, address: str) -> list[float]:
        horizon = self.clock() - FAILURE_WINDOW_S
        times = [t for t in self._failures.get(address, []) if t > horizon]
        if times:
            self._failures[address] = times
        else:
            self._failures.pop(address, None)
        return times

    def blocked(self, address: str) -> bool:
        if len(self._recent(address)) >= MAX_FAILURES:
            self.refused += 1
            return True
        return False

    def failed(self, address: str) -> None:
        self._failures.setdefault(address, []).append(self.clock())
        if len(self._failures) > 4096:  # a scan from many addresses: forget the oldest
            del self._failures[next(iter(self._failures))]

    def succeeded(self, address: str) -> None:
        self._failures.pop(address, None)
