"""Every place the OPC UA northbound's hardening reaches past asyncua's public API.

asyncua's server has no public way to do what the gateway needs below,
and in places its defaults are unsafe for a server that spins motors, so
it is done here, always, each on the one server instance, and checked by
``tests/opcua/test_opcua_hooks.py`` against the installed asyncua (the
``opcua`` extra pins the minor version). The other reaches are the speed
patches, :mod:`._speedups` (applied only on the asyncua releases they were
tested with, and never needed), and the subscription bounds,
:mod:`._subscriptions`:

- **Channels** (:func:`guard_channels`). The server gives every
  endpoint's policy factory the same permission ruleset; the handlers need
  the mode of the channel a request came by, so each factory gets a
  ruleset of its own mode. A client certificate outside
  ``trusted_clients`` is refused when the channel opens (asyncua checks
  it only at CreateSession, and only when the request carries one). And
  asyncua falls back to an unsecured channel when a client asks for
  SecurityPolicy None that no endpoint offers. Such a channel (and, with
  ``trusted_clients``, every unsecured one, which carries no certificate)
  serves discovery only: GetEndpoints and FindServers, which every client
  asks over an unsecured channel before it opens a secure one (OPC UA
  Part 4, 5.4), and no request of a session.
- **Sessions** (:func:`guard_sessions`). asyncua numbers authentication
  tokens 1000, 1001, ...: a client that guesses another's could activate
  that session on its own channel. Each session gets 32 random bytes
  instead. The northbound hears each session's creation (which it may
  refuse) and activation: :mod:`._admission` rations the unactivated and
  closes them in time (:func:`close_session`; asyncua would keep them as
  long as their connection), and a lease's connection is the session.
  :func:`session_count` counts the open ones (asyncua has no public count).
- **Requests** (:func:`guard_requests`, issue 41): asyncua's connection
  and request processing, for the servers handed to it, through the
  northbound's :class:`._defences.Door`: connections admitted by address;
  a chunk longer than the receive buffer refused at its header (asyncua
  buffered all it announced, up to 4 GiB); a session's message before any
  OpenSecureChannel refused (asyncua served it with no channel and no
  ruleset: reads past ``trusted_clients``); a chunk or a request asyncua
  cannot take closes its connection, counted, logged once at DEBUG
  (asyncua logged a traceback each and read on); CreateSession admitted
  and ActivateSession's user name token judged, awaited, before asyncua's
  synchronous activation (:mod:`._logins`), their refusals answered here
  without asyncua's ERROR line each. An asyncua processing otherwise than
  the releases tested (:data:`TESTED_ASYNCUA`) gets none of it, with a
  warning: passwords are then checked by the user manager, bounded.
- **Sessions closing** (:func:`on_session_closed`): a connection-scoped
  lease lapses when its OPC UA session closes.
- **Writes that wait for the line** (:func:`route_writes`): asyncua's
  write service stores a value and returns; a parameter write must go to
  the drive and answer with what became of it.
- **Operations per request** (:mod:`._operations`): asyncua advertises
  limits it does not enforce; a request over the gateway's is refused.
- **Discovery registration** (:func:`refuse_registration`): asyncua
  lets any client, without a session, register servers that FindServers
  then lists; the gateway is no discovery server.
- **Who watches a value** (:func:`follow_watchers`): asyncua says nowhere
  in its API whether a variable has monitored items. Reads are served from
  the gateway's bindings (a value callback), and the northbound pushes a
  value to asyncua only while some monitored item watches it (pushing
  every value for nobody was most of its CPU at 2,048 drives). So this is
  kept, always on, with the hardening: without it no subscription would
  hear a change. The gateway hears each data-change callback asyncua adds
  to or deletes from a Value attribute (its monitored items), on this
  server's address space only.
"""

from __future__ import annotations

import asyncio
import contextvars
import importlib.metadata
import inspect
import logging
import secrets
import weakref
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any, Final

from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.permission_rules import PermissionRuleset
from asyncua.crypto.security_policies import SecurityPolicyNone
from asyncua.server.binary_server_asyncio import OPCUAProtocol
from asyncua.server.uaprocessor import UaProcessor
from asyncua.ua import ua_binary

if TYPE_CHECKING:
    from ._defences import Door

__all__ = [
    "TESTED_ASYNCUA",
    "close_session",
    "follow_watchers",
    "guard_channels",
    "guard_requests",
    "guard_sessions",
    "on_session_closed",
    "refuse_registration",
    "route_writes",
    "session_count",
]

_log = logging.getLogger("sj300_async.gateway.opcua")

WriteHandler = Callable[[ua.WriteValue, Any], Awaitable[ua.StatusCode]]


class _Admitted:
    """A policy factory whose channels only admitted client certificates open.

    An unsecured channel carries no certificate to admit: it serves discovery only.
    """

    def __init__(
        self, inner: Any, admit: Callable[[bytes | None], bool], discovery: PermissionRuleset
    ) -> None:
        self._inner = inner
        self._admit = admit
        self._discovery = discovery

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    def matches(self, uri: str, mode: Any = None) -> bool:
        return bool(self._inner.matches(uri, mode))

    def create(self, peer_certificate: bytes | None) -> Any:
        if self._inner.mode == ua.MessageSecurityMode.None_:
            policy = self._inner.create(peer_certificate)
            policy.permissions = self._discovery
            return policy
        if not self._admit(peer_certificate):
            raise ua.uaerrors.BadUserAccessDenied  # asyncua closes the connection
        return self._inner.create(peer_certificate)


class _Unoffered:
    """Stands for SecurityPolicy None when no endpoint offers it: discovery only."""

    mode = ua.MessageSecurityMode.None_

    def __init__(self, discovery: PermissionRuleset) -> None:
        self.permission_ruleset = discovery

    def matches(self, uri: str, mode: Any = None) -> bool:
        return bool(uri == SecurityPolicyNone.URI)

    def create(self, peer_certificate: bytes | None) -> Any:
        return SecurityPolicyNone(permission_ruleset=self.permission_ruleset)


def guard_channels(
    server: Server,
    rules: Callable[[ua.MessageSecurityMode], PermissionRuleset],
    admit: Callable[[bytes | None], bool] | None,
    discovery: PermissionRuleset,
) -> None:
    """Per-mode rulesets, admitted certificates only, unoffered None for discovery only
    (*discovery*: the ruleset that refuses every request of a session; module docstring).

    Runs after ``server.start()``: the factories are made there. The list is the
    one every connection's processor selects from, so it is changed in place.
    """
    factories = server._policies
    offers_none = False
    for index, factory in enumerate(factories):
        factory.permission_ruleset = rules(factory.mode)
        offers_none |= factory.mode == ua.MessageSecurityMode.None_
        if admit is not None:
            factories[index] = _Admitted(factory, admit, discovery)
    if not offers_none:
        factories.append(_Unoffered(discovery))


def guard_sessions(
    server: Server,
    *,
    created: Callable[[Any, Any, bool], int | None],
    activated: Callable[[Any], None],
) -> None:
    """Random tokens; *created* (session, its peer, whether guard_requests admitted it:
    None or a status code refusing it) and *activated* hear each external session
    (module docstring)."""
    iserver = server.iserver
    create = iserver.create_session

    def create_session(name: Any, user: Any = None, external: bool = False) -> Any:
        session = create(name, external=external) if user is None else create(name, user, external)
        if not external:
            return session
        iserver.unregister_external_session(session)
        refused = created(session, name, _admitted.get())
        if refused is not None:
            raise ServiceError(refused)  # never registered: no client can reach it
        session.auth_token = ua.NodeId(secrets.token_bytes(32), 0, ua.NodeIdType.ByteString)
        iserver.register_external_session(session)
        activate = session.activate_session

        def activate_session(params: Any, peer_certificate: Any) -> Any:
            result = activate(params, peer_certificate)
            activated(session)
            return result

        session.activate_session = activate_session
        return session

    iserver.create_session = create_session


def session_count(server: Server) -> int:
    """The external sessions open on *server* (created, activated or not, not yet closed)."""
    return len(server.iserver._external_sessions)


def close_session(session: Any) -> None:
    """Close one of asyncua's sessions (its close is a coroutine: a task, whose failure is
    dropped: the session is being thrown away)."""
    task = asyncio.get_running_loop().create_task(session.close_session(True))
    task.add_done_callback(lambda done: done.cancelled() or done.exception())


def on_session_closed(server: Server, closed: Callable[[Any], None]) -> None:
    """Call *closed* with each external session as it closes."""
    iserver = server.iserver
    unregister = iserver.unregister_external_session

    def unregistered(session: Any) -> None:
        unregister(session)
        if session.state.name == "Closed":  # not the re-keying of guard_sessions
            closed(session)

    iserver.unregister_external_session = unregistered


class _RoutedWrites:
    """asyncua's attribute service, with the gateway's namespace's writes handed over."""

    def __init__(self, inner: Any, namespace: int, handler: WriteHandler) -> None:
        self._inner = inner
        self._namespace = namespace
        self._handler = handler

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    async def write(self, params: ua.WriteParameters, user: Any = None) -> list[ua.StatusCode]:
        ours = [value.NodeId.NamespaceIndex == self._namespace for value in params.NodesToWrite]
        if not any(ours):
            return list(await self._inner.write(params, user=user))
        results: list[ua.StatusCode] = []
        for value, own in zip(params.NodesToWrite, ours, strict=True):
            if own:
                results.append(await self._handler(value, user))
            else:
                single = ua.WriteParameters(NodesToWrite=[value])
                results.extend(await self._inner.write(single, user=user))
        return results


def route_writes(server: Server, namespace: int, handler: WriteHandler) -> None:
    """Hand every write to a node of *namespace* to *handler* (see the module docstring)."""
    iserver = server.iserver
    iserver.attribute_service = _RoutedWrites(iserver.attribute_service, namespace, handler)


def refuse_registration(server: Server) -> None:
    """RegisterServer and RegisterServer2 answer BadServiceUnsupported (module docstring)."""

    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise ServiceError(ua.StatusCodes.BadServiceUnsupported)

    server.iserver.register_server = refuse
    server.iserver.register_server2 = refuse


#: The asyncua releases guard_requests was written against and tested with; another is
#: guarded only where its processing has the same shape (_WRAPPED).
TESTED_ASYNCUA: Final = ("2.1.0",)
_CREATE: Final = ua.NodeId(ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary)
_ACTIVATE: Final = ua.NodeId(ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary)
#: What guard_requests wraps, and the parameters each has in the releases tested.
_WRAPPED: Final = {
    (OPCUAProtocol, "connection_made"): ["self", "transport"],
    (OPCUAProtocol, "connection_lost"): ["self", "ex"],
    (OPCUAProtocol, "data_received"): ["self", "data"],
    (OPCUAProtocol, "_process_one_msg"): ["self", "header", "buf"],
    (UaProcessor, "_process_message"): ["self", "typeid", "requesthdr", "seqhdr", "body"],
}
#: A frame of asyncua's binary decoding: what it raises there is the client's malformed bytes.
_DECODERS: Final = ("unpack", "from_binary", "deserial", "decode")


#: True while asyncua serves a CreateSession that guard_requests admitted.
_admitted: contextvars.ContextVar[bool] = contextvars.ContextVar("sj300_admitted", default=False)
#: Each guarded server's door, and the ruleset of its discovery-only channels.
_doors: weakref.WeakKeyDictionary[Any, tuple[Door, PermissionRuleset]] = weakref.WeakKeyDictionary()


def guard_requests(server: Server, door: Door, discovery: PermissionRuleset) -> bool:
    """Guard *server*'s connections and requests through *door* (module docstring); False,
    nothing guarded, when asyncua's processing is not of the shape wrapped (logged)."""
    unlike = [
        f"{owner.__name__}.{name}"
        for (owner, name), parameters in _WRAPPED.items()
        if list(inspect.signature(getattr(owner, name, _gone)).parameters) != parameters
    ]
    if unlike:
        _log.warning(
            "opcua: asyncua %s differs from %s where the gateway guards it (%s): connections "
            "not rationed, malformed requests left to asyncua, passwords checked on the "
            "event loop",
            importlib.metadata.version("asyncua"), ", ".join(TESTED_ASYNCUA), ", ".join(unlike),
        )  # fmt: skip
        return False
    _doors[server.iserver] = (door, discovery)
    if not getattr(OPCUAProtocol, "_sj300_guarded", False):
        _wrap_processing()
    return True


def _gone() -> None:
    """Stands for a method asyncua no longer has (its parameters match none)."""


def _wrap_processing() -> None:
    """Wrap asyncua's connection and request processing, once per process; a server not
    handed to guard_requests is processed exactly as asyncua does."""
    made, lost = OPCUAProtocol.connection_made, OPCUAProtocol.connection_lost
    received, process_one = OPCUAProtocol.data_received, OPCUAProtocol._process_one_msg
    process = UaProcessor._process_message

    def connection_made(self: Any, transport: Any) -> None:
        guarded = _doors.get(self.iserver)
        peer = transport.get_extra_info("peername")
        if guarded is not None:
            if not guarded[0].connection_opened(peer):
                transport.close()  # as asyncua refuses one past max_connections
                return
            self._sj300_peer = peer
        made(self, transport)

    def connection_lost(self: Any, ex: BaseException | None) -> None:
        lost(self, ex)
        guarded, peer = _doors.get(self.iserver), getattr(self, "_sj300_peer", None)
        if guarded is not None and peer is not None:
            guarded[0].connection_closed(peer)

    def data_received(self: Any, data: bytes) -> None:
        received(self, data)
        guarded, waiting = _doors.get(self.iserver), self._buffer  # a chunk's first part
        if guarded is None or self.transport is None or len(waiting) < 8:
            return
        if int.from_bytes(waiting[4:8], "little") > self.limits.max_recv_buffer:
            self._buffer = b""
            status = guarded[0].malformed(self.peer_name, "oversize", None, waiting[:32])
            _close_with(self.transport, status)

    async def process_one_msg(self: Any, header: Any, buf: Any) -> bool:
        guarded = _doors.get(self.iserver)
        if guarded is None or self.processor is None or self.transport is None:
            return bool(await process_one(self, header, buf))
        secure = header.MessageType in (ua.MessageType.SecureMessage, ua.MessageType.SecureClose)
        try:
            if secure and not self.processor._connection.is_open():
                status = guarded[0].malformed(self.peer_name, "unopened", None, bytes(buf)[:32])
            else:
                return bool(await process_one(self, header, buf))
        except Exception as exc:  # what asyncua logs with its traceback, and reads on
            status = guarded[0].malformed(self.peer_name, "chunk", exc, bytes(buf)[:32])
        _close_with(self.transport, status)
        return False

    async def process_message(
        self: Any, typeid: Any, requesthdr: Any, seqhdr: Any, body: Any
    ) -> Any:
        guarded = _doors.get(self.iserver)
        if guarded is None:
            return await process(self, typeid, requesthdr, seqhdr, body)
        door, discovery = guarded
        admitted = _admitted.set(False)
        try:
            status = None
            if typeid == _CREATE:
                policy = self._connection.security_policy
                status = door.admit(self.name, discovery=policy.permissions is discovery)
                _admitted.set(status is None)
            elif typeid == _ACTIVATE:
                status = await _login(self, door, requesthdr, body)
            if status is None:
                return await process(self, typeid, requesthdr, seqhdr, body)
        except ServiceError as exc:
            if exc.code != ua.StatusCodes.BadTooManyOperations:
                raise  # asyncua answers it as it does
            status = exc.code  # counted by _operations; answered without asyncua's ERROR line
        except Exception as exc:
            if not _decoding(exc):
                raise  # ours or asyncua's own failure: asyncua answers and logs it
            door.malformed(self.name, "request", exc, bytes(body)[:32])
            _fault(self, requesthdr, seqhdr, ua.StatusCodes.BadDecodingError)
            return False  # asyncua closes the connection
        finally:
            _admitted.reset(admitted)
        _fault(self, requesthdr, seqhdr, status)
        return True

    OPCUAProtocol.connection_made = connection_made
    OPCUAProtocol.connection_lost = connection_lost
    OPCUAProtocol.data_received = data_received
    OPCUAProtocol._process_one_msg = process_one_msg
    UaProcessor._process_message = process_message
    OPCUAProtocol._sj300_guarded = True


async def _login(processor: Any, door: Door, requesthdr: Any, body: Any) -> int | None:
    """*door*'s judgement of an ActivateSession's user name token (None: asyncua goes on)."""
    params = ua_binary.struct_from_binary(ua.ActivateSessionParameters, body.copy())
    token = params.UserIdentityToken
    session = processor.session or processor.iserver.lookup_external_session(
        requesthdr.AuthenticationToken
    )
    if not isinstance(token, ua.UserNameIdentityToken) or session is None:
        return None  # asyncua's own answer (anonymous; no such session)
    policy = processor._connection.security_policy
    channel = (policy.URI, policy.Mode, processor.iserver.endpoints)
    return await door.login(
        processor.name, token, channel, lambda: processor.iserver.decrypt_user_token(session, token)
    )


def _fault(processor: Any, requesthdr: Any, seqhdr: Any, status: int) -> None:
    response = ua.ServiceFault()
    response.ResponseHeader.ServiceResult = ua.StatusCode(status)
    processor.send_response(requesthdr.RequestHandle, seqhdr, response)


def _close_with(transport: Any, status: int) -> None:
    """An Error message, then the connection closed (OPC UA Part 6, 7.1.5)."""
    error = ua.ErrorMessage(ua.StatusCode(status), ua.StatusCode(status).name)
    transport.write(ua_binary.uatcp_to_binary(ua.MessageType.Error, error))
    transport.close()


def _decoding(exc: BaseException) -> bool:
    """Whether *exc* came from decoding a client's bytes (a frame of asyncua's decoders)."""
    trace = exc.__traceback__
    while trace is not None:
        code = trace.tb_frame.f_code
        if code.co_filename.endswith(("ua_binary.py", "utils.py")) and any(
            word in code.co_name for word in (*_DECODERS, "read")
        ):
            return True
        trace = trace.tb_next
    return False


def follow_watchers(server: Server, changed: Callable[[ua.NodeId, int], None]) -> None:
    """Tell *changed* (node, +1 or -1) of each monitored item added to or deleted from a value.

    See the module docstring. asyncua's address space adds and deletes the
    data-change callbacks of monitored items (``add_datachange_callback``,
    ``delete_datachange_callback``); both are wrapped on this server's
    address space only.
    """
    space = server.iserver.aspace
    add, delete = space.add_datachange_callback, space.delete_datachange_callback
    handles: dict[int, ua.NodeId] = {}

    def added(nodeid: ua.NodeId, attr: ua.AttributeIds, callback: Any) -> Any:
        result = add(nodeid, attr, callback)
        status, handle = result
        if attr == ua.AttributeIds.Value and status.is_good():
            handles[handle] = nodeid
            changed(nodeid, 1)
        return result

    def deleted(handle: int) -> None:
        delete(handle)
        nodeid = handles.pop(handle, None)
        if nodeid is not None:
            changed(nodeid, -1)

    space.add_datachange_callback = added
    space.delete_datachange_callback = deleted
