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
"""

from __future__ import annotations

import contextvars
import itertools
from dataclasses import dataclass
from typing import Any, Final

from asyncua import ua
from asyncua.crypto.permission_rules import PermissionRuleset, UserRole
from asyncua.crypto.permission_rules import User as UaUser

from .. import User, verify_password

__all__ = ["Caller", "ChannelRules", "Principal", "Users", "current_caller"]

_NODE_MANAGEMENT: Final = frozenset(
    ua.NodeId(identifier)
    for identifier in (
        ua.ObjectIds.AddNodesRequest_Encoding_DefaultBinary,
        ua.ObjectIds.DeleteNodesRequest_Encoding_DefaultBinary,
        ua.ObjectIds.AddReferencesRequest_Encoding_DefaultBinary,
        ua.ObjectIds.DeleteReferencesRequest_Encoding_DefaultBinary,
    )
)
_sessions = itertools.count(1)


@dataclass(eq=False)
class Principal(UaUser):  # type: ignore[misc]
    """An activated session's user: a configured name, or anonymous (``name`` None)."""

    #: Unique per activation: names the session's connection for a connection-scoped lease.
    key: int = 0

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

    @property
    def encrypted(self) -> bool:
        return bool(self.mode == ua.MessageSecurityMode.SignAndEncrypt)


_caller: contextvars.ContextVar[Caller | None] = contextvars.ContextVar(
    "sj300_opcua_caller", default=None
)


def current_caller() -> Caller | None:
    """The caller of the request being served (None outside a request)."""
    return _caller.get()


class Users:
    """asyncua's user manager over ``[[opcua.users]]`` (anonymous sessions read only)."""

    def __init__(self, users: tuple[User, ...]) -> None:
        self._hashes = {user.name: user.password_hash for user in users}
        #: Failed password checks (each is also asyncua's BadUserAccessDenied).
        self.refused = 0

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> Principal | None:
        key = next(_sessions)
        if username is None:
            return Principal(role=UserRole.Anonymous, name=None, key=key)
        stored = self._hashes.get(username)
        # The hash is checked for unknown names too (against a fixed one): the time
        # a refusal takes does not tell which names exist.
        verified = verify_password(password or "", stored or _DUMMY_HASH)
        if stored is None or not verified:
            self.refused += 1
            return None
        return Principal(role=UserRole.User, name=username, key=key)


class ChannelRules(PermissionRuleset):  # type: ignore[misc]
    """The permission ruleset of one security mode's endpoints (see the module docstring)."""

    def __init__(self, mode: ua.MessageSecurityMode) -> None:
        self.mode = mode

    def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
        if action_type_id in _NODE_MANAGEMENT:
            return False
        principal = user if isinstance(user, Principal) else Principal(name=None)
        _caller.set(Caller(principal, self.mode))
        return True


#: A valid scrypt hash of a random password nobody knows (the timing of unknown names).
_DUMMY_HASH: Final = (
    "scrypt$16384$8$1$c2ozMDAtYXN5bmMtZHVtbXk=$2xJ1dWJXKYvTgvtn0hvDxrxAgG2o1vXjS3Tm2v0Mrjk="
)
