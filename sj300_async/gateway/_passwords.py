"""Who may write through a northbound that names its people: users with scrypt-hashed passwords.

The HTTP northbound (``[[http.users]]``) and the OPC UA one
(``[[opcua.users]]``) name the people who may write the same way: a name
and a ``password_hash`` that ``sj300 gateway --hash-password`` makes. One
reader of those tables (:func:`parse_users`), so both report a bad entry
with the same words, and one hashing.

Decisions: passwords are stored as scrypt hashes (the standard library's
:func:`hashlib.scrypt`, n=2**14, r=8, p=1, 16 random bytes of salt):
memory-hard, so a stolen configuration file is slow to attack; compared in
constant time. A hash weaker than n=1024 is refused when the configuration
is read.

A check costs about 65 ms of one core. The gateway's event loop also polls
the lines and runs the lapse stops, so a door never checks a password on
it: :class:`PasswordChecks` runs the checks in a thread (hashlib's scrypt
releases the GIL), :data:`CHECK_THREADS` at a time in the whole process,
with at most :data:`CHECKS_QUEUED` more waiting per door; past that a check
is refused unchecked
(``None``: the door answers "busy" and counts it). One thread, not one per
core: a burst then takes one core and leaves the other to the loop, and
the queue bounds how long a legitimate login waits behind it (about
:data:`CHECKS_QUEUED` x 65 ms). The doors spend their per-address and
per-name budgets (:mod:`._budget`) before they ask, so the queue is the
last guard, not the first.
"""

from __future__ import annotations

import asyncio
import base64
import concurrent.futures
import contextlib
import hashlib
import hmac
import re
import secrets
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from ._toml import ConfigTable

__all__ = [
    "CHECKS_QUEUED",
    "CHECK_THREADS",
    "USER_NAME",
    "PasswordChecks",
    "User",
    "hash_password",
    "named_entries",
    "parse_password_hash",
    "parse_users",
    "verify_password",
]

#: A user's or a token's name: it shows in the audit log.
USER_NAME: Final = re.compile(r"[A-Za-z0-9_.@-]{1,64}\Z")


@dataclass(frozen=True, slots=True)
class User:
    """A person who may log in and write (``[[http.users]]``, ``[[opcua.users]]``)."""

    name: str
    password_hash: str


_SCRYPT_N: Final = 2**14
_SCRYPT_R: Final = 8
_SCRYPT_P: Final = 1
_SALT_BYTES: Final = 16
_HASH_BYTES: Final = 32


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """``scrypt$16384$8$1$SALT$HASH`` (base64): what ``password_hash`` holds."""
    salt = secrets.token_bytes(_SALT_BYTES) if salt is None else salt
    digest = hashlib.scrypt(
        password.encode("utf-8"), salt=salt, n=_SCRYPT_N, r=_SCRYPT_R, p=_SCRYPT_P,
        dklen=_HASH_BYTES,
    )  # fmt: skip
    return f"scrypt${_SCRYPT_N}${_SCRYPT_R}${_SCRYPT_P}${_b64(salt)}${_b64(digest)}"


def parse_password_hash(stored: str) -> tuple[int, int, int, bytes, bytes]:
    """The parts of a stored hash.

    Raises:
        ValueError: not one :func:`hash_password` makes (the message says what).
    """
    parts = stored.split("$")
    if len(parts) != 6 or parts[0] != "scrypt":
        raise ValueError("expected scrypt$N$R$P$SALT$HASH (sj300 gateway --hash-password)")
    try:
        n, r, p = (int(x) for x in parts[1:4])
        salt = base64.b64decode(parts[4], validate=True)
        digest = base64.b64decode(parts[5], validate=True)
    except ValueError:
        raise ValueError(
            "a scrypt hash's N, R, P are numbers and its salt and hash base64"
        ) from None
    if n < 2**10 or n & (n - 1) or not 1 <= r <= 64 or not 1 <= p <= 16 or len(digest) < 16:
        raise ValueError("a scrypt hash too weak or malformed (N a power of 2 >= 1024)")
    return n, r, p, salt, digest


def verify_password(password: str, stored: str) -> bool:
    """True when *password* is the one *stored* was made from (constant-time compare)."""
    try:
        n, r, p, salt, digest = parse_password_hash(stored)
    except ValueError:
        return False
    candidate = hashlib.scrypt(
        password.encode("utf-8"), salt=salt, n=n, r=r, p=p, dklen=len(digest),
        maxmem=256 * 1024 * 1024,
    )  # fmt: skip
    return hmac.compare_digest(candidate, digest)


#: Password checks running at once in the process (threads), and waiting beyond them,
#: per :class:`PasswordChecks` (per door).
CHECK_THREADS: Final = 1
CHECKS_QUEUED: Final = 8


_executor: concurrent.futures.ThreadPoolExecutor | None = None


def _checking_thread() -> concurrent.futures.ThreadPoolExecutor:
    """The process's one password-checking thread, made when first needed."""
    global _executor
    if _executor is None:
        _executor = concurrent.futures.ThreadPoolExecutor(
            max_workers=CHECK_THREADS, thread_name_prefix="sj300-password"
        )
    return _executor


class PasswordChecks:
    """Password checks off the event loop, bounded (see the module docstring).

    Every door has its own (its own queue and counts), and all of them share the
    process's one checking thread: a flood of logins on two doors at once still takes
    one core, not two, and leaves the other to the loop.

    Args:
        queued: checks this door may have submitted and not finished beyond the one
            running; past them, :meth:`verify` refuses.
    """

    def __init__(self, queued: int = CHECKS_QUEUED) -> None:
        self._capacity = CHECK_THREADS + queued
        self._futures: set[concurrent.futures.Future[bool]] = set()
        self._closed = False
        #: Checks submitted and not finished (a cancelled waiter's check still runs).
        self.pending = 0
        #: Checks run, and checks refused because the queue was full, since the start.
        self.checked = 0
        self.busy = 0

    async def verify(self, password: str, stored: str) -> bool | None:
        """True or False as :func:`verify_password` says; None when too many are pending.

        The caller's task may be cancelled while it waits (a client that went
        away): the check then finishes in its thread and still counts as pending
        until it does, so a flood of abandoned logins cannot grow the queue.
        """
        if self._closed or self.pending >= self._capacity:
            self.busy += 1
            return None
        loop = asyncio.get_running_loop()
        self.pending += 1
        self.checked += 1
        future = _checking_thread().submit(verify_password, password, stored)
        self._futures.add(future)

        def finished(done: concurrent.futures.Future[bool]) -> None:
            # In the worker thread: the count is the loop's, so it is changed there.
            # A loop already closed (the process stopping) has nobody left to tell.
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._finished, done)

        future.add_done_callback(finished)
        return await asyncio.wrap_future(future, loop=loop)

    def _finished(self, future: concurrent.futures.Future[bool]) -> None:
        self._futures.discard(future)
        self.pending -= 1

    def close(self) -> None:
        """Refuse new checks and cancel this door's waiting ones (a running one finishes)."""
        self._closed = True
        for future in list(self._futures):
            future.cancel()


def _password_problem(stored: str) -> str | None:
    try:
        parse_password_hash(stored)
    except ValueError as exc:
        return str(exc)
    return None


def named_entries(
    table: ConfigTable, key: str, noun: str, field: str, check: Callable[[str], str | None]
) -> dict[str, str]:
    """``[[SECTION.KEY]]``'s entries: each *field* by its unique ``name``; *check* says what
    is wrong with a *field*, or None."""
    found: dict[str, str] = {}
    for i, item in enumerate(table.tables(key, f"{table.path}.{key}")):
        entry = ConfigTable(table.ctx, f"{table.path}.{key}[{i}]", item, ("name", field))
        name = entry.required_string("name")
        if not USER_NAME.match(name):
            raise entry.error("name", f"expected 1..64 of A-Z a-z 0-9 _ . @ -, got {name!r}")
        if name in found:
            raise entry.error("name", f"{noun} {name!r} is named twice")
        stored = entry.required_string(field)
        problem = check(stored)
        if problem is not None:
            raise entry.error(field, problem)
        found[name] = stored
    return found


def parse_users(table: ConfigTable, key: str = "users") -> tuple[User, ...]:
    """The users of ``[[SECTION.KEY]]`` (name and ``password_hash``), checked."""
    found = named_entries(table, key, "user", "password_hash", _password_problem)
    return tuple(User(name, stored) for name, stored in found.items())
