"""The OPC UA door's defences put together: what they guard, what they count.

A client that has proved nothing can make the server work: a connection,
a session, a password check, a chunk to decode. Issue 41 found each of
them costly with asyncua's defaults, on the event loop that also polls the
lines and runs the lapse stops. :class:`Defences` is the door
:mod:`._hooks` asks before that work (connections and unactivated
sessions: :mod:`._admission`; logins: :mod:`._logins`), and the one place
a malformed message is counted and logged (here: a client's bytes are not
the gateway's failure, so one DEBUG line with a bounded excerpt each, and
the connection closed, after asyncua's error message). Its counters are
the ``sj300_opcua_refused_*`` and ``sj300_opcua_malformed_total`` metrics
(docs/OPCUA.md, "Hardening").

Decisions:

- **Counted before logged.** Every refusal is a metric; only what an
  engineer needs to read is logged. The refusals are DEBUG lines: a flood
  of them is the attack, not news, and the counters show it.
- **One door per server**, with its own password thread, closed with the
  northbound.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Final

from asyncua import Server, ua

from .. import PasswordChecks, excerpt
from ._admission import Admission, Peer, SessionLimits
from ._config import OpcuaConfig
from ._hooks import close_session, guard_requests, guard_sessions, on_session_closed
from ._logins import Channel, LoginLimits, Logins
from ._security import DiscoveryOnly, Users

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["Defences", "Door"]

_log = logging.getLogger("sj300_async.gateway.opcua")

#: The Error message a malformed message is answered with before its connection closes
#: (OPC UA Part 6, 7.1.5); a chunk's own status code where asyncua's error carries one.
_ANSWERS: Final = {
    "oversize": ua.StatusCodes.BadTcpMessageTooLarge,
    "unopened": ua.StatusCodes.BadTcpSecureChannelUnknown,
    "chunk": ua.StatusCodes.BadSecurityChecksFailed,
    "request": ua.StatusCodes.BadDecodingError,
}
#: The label values each family always shows (zero until counted).
_LOGIN_REASONS: Final = ("password", "rate", "busy", "unencrypted", "token", "certificate")
_SESSION_REASONS: Final = (
    "per_connection", "per_address", "unactivated_per_address", "discovery", "full", "expired",
    "evicted",
)  # fmt: skip


class Door:
    """What :func:`._hooks.guard_requests` asks before the work (see the module docstring)."""

    def __init__(self, admission: Admission, logins: Logins) -> None:
        self.admission = admission
        self.logins = logins
        #: Malformed messages, by kind (each closed its connection).
        self.malformed_counts: Counter[str] = Counter()

    def connection_opened(self, peer: Peer) -> bool:
        return self.admission.connection_opened(peer)

    def connection_closed(self, peer: Peer) -> None:
        self.admission.connection_closed(peer)

    def admit(self, peer: Peer, *, discovery: bool) -> int | None:
        return self.admission.admit(peer, discovery=discovery)

    async def login(
        self,
        peer: Peer,
        token: ua.UserNameIdentityToken,
        channel: tuple[str, ua.MessageSecurityMode, Any],
        decrypt: Callable[[], tuple[str, str]],
    ) -> int | None:
        address = peer[0] if peer else peer
        return await self.logins.judge(address, token, Channel(*channel), decrypt)

    def malformed(self, peer: Peer, kind: str, error: BaseException | None, head: bytes) -> int:
        """Count a malformed message of *peer*; the status code of the Error message to it."""
        self.malformed_counts[kind] += 1
        code = getattr(error, "code", None)
        status = code if kind == "chunk" and isinstance(code, int) else _ANSWERS[kind]
        _log.debug(
            "opcua: closed the connection of %s: a malformed message (%s%s), its head %s",
            peer, kind, f": {excerpt(str(error), 160)}" if error else "", head[:32].hex(),
        )  # fmt: skip
        return int(status)


#: Why a request was refused whole.
_REQUEST_REASONS: Final = ("too_many_operations",)


class Defences:
    """The door's defences for one server (see the module docstring)."""

    def __init__(self, config: OpcuaConfig, users: Users) -> None:
        limits = _session_limits(config)
        self.users = users
        #: The ruleset of a channel that may only discover the server (._hooks).
        self.discovery = DiscoveryOnly()
        self.admission = Admission(limits, close_session)
        self.checks = PasswordChecks()
        budget = LoginLimits(config.login_burst, config.login_interval_s)
        logins = Logins(users, budget, self.checks)
        self.door = Door(self.admission, logins)
        #: Whether asyncua's request processing is guarded (False: an asyncua unlike the
        #: releases tested; _hooks warned).
        self.guarded = False
        #: Requests refused whole, by reason (:mod:`._operations`).
        self.requests_refused: dict[str, int] = dict.fromkeys(_REQUEST_REASONS, 0)

    def retune(self, config: OpcuaConfig) -> None:
        """A reload's limits from the next connection, session or login (the sessions
        open stay, even over a lower cap; each address's login budget keeps its use)."""
        self.admission.limits = _session_limits(config)
        logins, per_s = self.door.logins, 1.0 / config.login_interval_s
        logins.by_address.burst, logins.by_address.per_s = float(config.login_burst), per_s
        logins.by_name.burst, logins.by_name.per_s = 2.0 * config.login_burst, 2 * per_s

    def refuse_operations(self) -> None:
        """A request held more operations than one may (:mod:`._operations`)."""
        self.requests_refused["too_many_operations"] += 1

    def install(
        self,
        server: Server,
        *,
        created: Callable[[Any], None],
        activated: Callable[[Any], None],
        closed: Callable[[Any], None],
    ) -> None:
        """Guard *server*; the northbound hears each session created, activated, closed."""
        admission = self.admission

        def session_created(session: Any, peer: Peer, admitted: bool) -> int | None:
            refused = admission.created(session, peer, admitted=admitted)
            if refused is None:
                created(session)
            return refused

        def session_activated(session: Any) -> None:
            admission.activated(session)
            activated(session)

        def session_closed(session: Any) -> None:
            admission.closed(session)
            closed(session)

        guard_sessions(server, created=session_created, activated=session_activated)
        on_session_closed(server, session_closed)
        self.guarded = guard_requests(server, self.door, self.discovery)

    def refuse_certificate(self) -> None:
        self.users.refusals["certificate"] += 1

    def metrics(self) -> Iterable[Metric]:
        from prometheus_client.core import CounterMetricFamily

        families = (
            (
                "sj300_opcua_refused_logins",
                "Logins refused: a wrong user or password, the password budget spent, the "
                "checks busy, a token not encrypted as its policy asks or not decryptable, an "
                "untrusted certificate.",
                "reason", _LOGIN_REASONS, self.users.refusals,
            ),
            (
                "sj300_opcua_refused_sessions",
                "Sessions refused at creation (a connection's or an address's share, an "
                "address's unactivated ones, a discovery-only channel, every slot activated) "
                "or closed unactivated (expired, evicted).",
                "reason", _SESSION_REASONS, self.admission.sessions_refused,
            ),
            (
                "sj300_opcua_refused_connections",
                "Connections refused: their client address held its share.",
                "reason", ("per_address",), self.admission.connections_refused,
            ),
            (
                "sj300_opcua_refused_requests",
                "Requests refused whole: more operations (nodes, items, calls) than one may "
                "hold.",
                "reason", _REQUEST_REASONS, self.requests_refused,
            ),
            (
                "sj300_opcua_malformed",
                "Malformed messages, each closing its connection, by kind.",
                "kind", tuple(_ANSWERS), self.door.malformed_counts,
            ),
        )  # fmt: skip
        for name, text, label, values, counts in families:
            family = CounterMetricFamily(name, text, labels=[label])
            for value in values:
                family.add_metric([value], counts[value])
            yield family

    def close(self) -> None:
        self.admission.close()
        self.checks.close()


def _session_limits(config: OpcuaConfig) -> SessionLimits:
    return SessionLimits(
        sessions=config.max_connections,
        max_connections_per_address=config.max_connections_per_address,
        max_unactivated_per_address=config.max_unactivated_per_address,
        activate_within_s=config.activate_within_s,
    )
