"""Who is calling: the users from the configuration, and the channel each request came by.

asyncua authenticates a session's user through a user manager
(:class:`Users`: the configured names and scrypt hashes; anonymous
sessions are :data:`ANONYMOUS`'s role) and checks each request against
the permission ruleset of the secure channel's policy. Our ruleset
(:class:`ChannelRules`, one per endpoint's security mode) does two things:

- it refuses what no client of the gateway may do, whoever it is: adding
  or deleting nodes and references (asyncua would otherwise let any
  session change the address space);
- it records who is asking and over which channel (:class:`Caller`) in a
  context variable, which the method and write handlers read: asyncua
  hands a method only its arguments. The ruleset runs inside the
  connection's task, right before the request is served, so the variable
  holds this request's caller when its handler runs.

Writes (methods, writable variables) need an authenticated user on a
SignAndEncrypt channel; everything else (browse, read, subscribe) is open
to every session, anonymous included. The handlers judge that, so each
refused call gets its own status code instead of the whole request
failing.

Password checks are scrypt (about 65 ms of a core each), and asyncua asks
for them synchronously, on the event loop that also polls the lines and
runs the lapse stops. So :mod:`._logins` checks each password first, off
the loop, within budgets per client address and per name, awaited by
:mod:`._hooks` before asyncua's activation runs, and hands the login it
accepted over (:func:`hand_over`): :class:`Users` then answers asyncua from
it. Only where asyncua's request processing could not be reached (an
asyncua release the hooks do not know) does :class:`Users` check a
password itself, on the loop, within a budget shared by every client
(:data:`CHECKS_BURST` at once, :data:`CHECKS_PER_S` after): bounded, and
that path's refusals counted too.
"""

from __future__ import annotations

import contextvars
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any, Final

from asyncua import ua
from asyncua.crypto.permission_rules import PermissionRuleset, UserRole
from asyncua.crypto.permission_rules import User as UaUser

from .. import User, verify_password

__all__ = [
    "DUMMY_HASH",
    "MAX_OPERATIONS",
    "Caller",
    "ChannelRules",
    "DiscoveryOnly",
    "Principal",
    "Users",
    "current_caller",
    "hand_over",
]

_NODE_MANAGEMENT: Final = frozenset(
    ua.NodeId(identifier)
    for identifier in (
        ua.ObjectIds.AddNodesRequest_Encoding_DefaultBinary,
        ua.ObjectIds.DeleteNodesRequest_Encoding_DefaultBinary,
        ua.ObjectIds.AddReferencesRequest_Encoding_DefaultBinary,
        ua.ObjectIds.DeleteReferencesRequest_Encoding_DefaultBinary,
    )
)
#: Password checks allowed at once, and per second after, where Users checks them itself.
CHECKS_BURST: Final = 3
CHECKS_PER_S: Final = 1.0
#: Operations (method calls, variable writes) one request may carry.
MAX_OPERATIONS: Final = 64


@dataclass(eq=False)
class Principal(UaUser):  # type: ignore[misc]
    """An activated session's user: a configured name, or anonymous (``name`` None)."""

    #: The session's number (set when the session is activated): a connection-scoped
    #: lease names the session it was renewed by.
    key: int = 0
    #: The password hash the session was activated against: a reload that removes the
    #: user or changes the password makes the session anonymous (read only).
    credential: str | None = None

    @property
    def anonymous(self) -> bool:
        return self.name is None

    @property
    def client(self) -> str:
        """The name the lease and the audit log know it by."""
        return f"opcua:{self.name or 'anonymous'}"

    @property
    def connection(self) -> str:
        return f"opcua#{self.key}"


@dataclass(frozen=True, slots=True)
class Caller:
    """Who made the request being served, and the channel's security mode."""

    principal: Principal
    mode: ua.MessageSecurityMode
    #: Operations of this request so far (see :data:`MAX_OPERATIONS`).
    operations: list[int]

    def operation(self) -> bool:
        """Count one operation of the request; False past :data:`MAX_OPERATIONS`."""
        self.operations[0] += 1
        return self.operations[0] <= MAX_OPERATIONS

    @property
    def encrypted(self) -> bool:
        return bool(self.mode == ua.MessageSecurityMode.SignAndEncrypt)


_caller: contextvars.ContextVar[Caller | None] = contextvars.ContextVar(
    "sj300_opcua_caller", default=None
)


def current_caller() -> Caller | None:
    """The caller of the request being served (None outside a request)."""
    return _caller.get()


#: The login :mod:`._logins` accepted for the ActivateSession being served: (name, password).
_accepted: contextvars.ContextVar[tuple[str, str] | None] = contextvars.ContextVar(
    "sj300_opcua_accepted", default=None
)


def hand_over(name: str, password: str) -> None:
    """The login of the ActivateSession being served is accepted: asyncua's synchronous
    question that follows, in this task, is answered from it (see the module docstring)."""
    _accepted.set((name, password))


class Users:
    """asyncua's user manager over ``[[opcua.users]]`` (anonymous sessions read only)."""

    def __init__(self, users: tuple[User, ...]) -> None:
        self._hashes = {user.name: user.password_hash for user in users}
        #: Logins refused, by reason (the metric's label): ``password``, ``rate``,
        #: ``busy``, ``unencrypted``, ``token`` (each also a refusal asyncua answers).
        self.refusals: Counter[str] = Counter()
        self._budget = float(CHECKS_BURST)
        self._budget_at = time.monotonic()

    def stored(self, name: str) -> str | None:
        """The password hash of the user *name* (None: no such user)."""
        return self._hashes.get(name)

    def replace(self, users: tuple[User, ...]) -> None:
        """Who may log in from now on (a reload); activated sessions: :meth:`current`."""
        self._hashes = {user.name: user.password_hash for user in users}

    def current(self, principal: Principal) -> Principal:
        """*principal* as the users are now: anonymous (read only) when its user was
        removed or its password changed since the session was activated."""
        if principal.name is None or self._hashes.get(principal.name) == principal.credential:
            return principal
        return Principal(role=UserRole.Anonymous, name=None, key=principal.key)

    def _afford(self) -> bool:
        now = time.monotonic()
        self._budget = min(CHECKS_BURST, self._budget + (now - self._budget_at) * CHECKS_PER_S)
        self._budget_at = now
        if self._budget < 1.0:
            return False
        self._budget -= 1.0
        return True

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> Principal | None:
        if username is None:
            return Principal(role=UserRole.Anonymous, name=None)
        accepted = _accepted.get()
        if accepted is not None:
            _accepted.set(None)  # once: the next activation is judged again
            if accepted == (username, password):
                return Principal(
                    role=UserRole.User, name=username, credential=self._hashes.get(username)
                )
        # Not judged before (the hooks could not reach asyncua's processing): on the
        # loop, within the shared budget.
        if not self._afford():
            self.refusals["rate"] += 1
            return None
        stored = self._hashes.get(username)
        # The hash is checked for unknown names too (against a fixed one): the time
        # a refusal takes does not tell which names exist.
        verified = verify_password(password or "", stored or DUMMY_HASH)
        if stored is None or not verified:
            self.refusals["password"] += 1
            return None
        return Principal(role=UserRole.User, name=username, credential=stored)


class ChannelRules(PermissionRuleset):  # type: ignore[misc]
    """The permission ruleset of one security mode's endpoints (see the module docstring)."""

    def __init__(self, mode: ua.MessageSecurityMode, users: Users | None = None) -> None:
        self.mode = mode
        self.users = users

    def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
        if action_type_id in _NODE_MANAGEMENT:
            return False
        principal = user if isinstance(user, Principal) else Principal(name=None)
        if self.users is not None:
            principal = self.users.current(principal)
        _caller.set(Caller(principal, self.mode, [0]))
        return True


#: A valid scrypt hash of a random password nobody knows (the timing of unknown names).
DUMMY_HASH: Final = (
    "scrypt$16384$8$1$c2ozMDAtYXN5bmMtZHVtbXk=$2xJ1dWJXKYvTgvtn0hvDxrxAgG2o1vXjS3Tm2v0Mrjk="
)


class DiscoveryOnly(PermissionRuleset):  # type: ignore[misc]
    """The ruleset of a channel that may only discover the server (see _hooks.guard_channels).

    asyncua checks no ruleset for GetEndpoints, FindServers, CreateSession and
    ActivateSession; every other request, a session's, is refused here.
    """

    def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
        return False
