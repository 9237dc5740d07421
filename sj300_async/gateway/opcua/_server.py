"""The OPC UA northbound: an asyncua server over the gateway's drives.

Decisions:

- **Quality is the core's.** A drive value's quality is the drive as
  served's (:class:`~sj300_async.gateway.ServedDrive`, built once per
  snapshot): its group's deadline and the order of the verdicts are the
  gateway's, the same for every northbound; :mod:`._quality` only words it
  as a status code (:mod:`._model` says which variables keep a rule of
  their own).
- **Reads never wait for a push.** Each drive variable is served by a
  read callback from its :class:`~._model.Binding`, which takes the drive's
  latest served view and asks it the quality at the moment of the read (a
  value goes Uncertain past its group's served deadline whether or not a
  sample arrived). Subscriptions
  are fed by pushing a value to asyncua only when its value or its status
  changed: a sample that changes nothing costs no notification, and
  OPC UA's default trigger (status and value) would drop a
  timestamp-only change anyway.
- **publish never blocks.** It compares and leaves the changed values in
  an outbox (the latest per node); one task pushes them. A ticker (once a
  second) pushes the quality changes time alone makes (Good past its
  served deadline: Uncertain) and the lines' counters.
- **Writes** are :mod:`._calls`'s; asyncua's own write path is kept for
  nothing of ours (:mod:`._hooks`).
- **Speed patches** (:mod:`._speedups`) only where tested: elsewhere values
  are plain DataValues, each pushed by asyncua's ``write_attribute_value``.
- **Security**: :mod:`._security`; the certificate: :mod:`._certificate`; what a
  client that proved nothing may cost: :mod:`._defences`.

asyncua is imported with this module, when the northbound is created.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import functools
import itertools
import logging
import time
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Final

from asyncua import Server, ua
from asyncua.common.connection import TransportLimits
from asyncua.crypto import uacrypto
from asyncua.server.address_space import AddressSpace, NodeData
from cryptography import x509

from .. import (
    GatewayDrive,
    GatewayStartError,
    GatewayView,
    ServedDrive,
    ServedLine,
)
from ._calls import Calls
from ._certificate import ServerCertificate, free_port, load_or_generate, load_trusted
from ._config import OpcuaConfig, certificate_error
from ._defences import Defences
from ._hooks import (
    follow_watchers,
    guard_channels,
    refuse_registration,
    route_writes,
    session_count,
)
from ._lazy import LazyNodes, Shape
from ._model import Binding, DriveNodes, LineNodes
from ._nodeset import initialised
from ._operations import limit_operations
from ._quality import GOOD
from ._relines import add_lines, finish_lines, gather_lines, remove_line
from ._security import ChannelRules, Principal, Users
from ._server_metrics import server_metrics
from ._space import SpaceBuilder
from ._speedups import ENABLED as SPEEDUPS_ENABLED
from ._speedups import install as install_speedups
from ._speedups import push_frozen
from ._subscriptions import bound_subscriptions
from ._trip_events import TripEvents
from ._values import LineCounters, drive_datavalue

if TYPE_CHECKING:
    from prometheus_client.core import Metric

    from ..recorder import RecordSummary

__all__ = ["OpcuaServer"]

_log = logging.getLogger("sj300_async.gateway.opcua")

#: How often the quality that time alone changes, and the lines' counters, are pushed.
TICK_S: Final = 1.0
#: The largest request taken (asyncua's default is 100 MB).
MAX_MESSAGE_BYTES: Final = 4 * 1024 * 1024
#: Requests queued per connection while one is served (asyncua's default is 500).
MAX_PENDING_MESSAGES: Final = 64
#: The keys of ``[opcua]`` a reload changes on the running server (reconfigure).
_LIVE_KEYS: Final = (
    "users", "max_connections", "max_connections_per_address",
    "max_unactivated_per_address", "activate_within_s", "login_burst", "login_interval_s",
)  # fmt: skip
_POLICIES: Final = {
    "Basic256Sha256_SignAndEncrypt": ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
    "Basic256Sha256_Sign": ua.SecurityPolicyType.Basic256Sha256_Sign,
    "None": ua.SecurityPolicyType.NoSecurity,
}


class OpcuaServer:
    """The OPC UA northbound (see the module docstring)."""

    def __init__(self, config: OpcuaConfig) -> None:
        self.config = config
        self.url = config.url
        self.certificate: ServerCertificate | None = None
        self.namespace = 0
        self.startup_s = 0.0
        #: Values pushed to asyncua for its subscriptions.
        self.pushed = 0
        #: Values that could not be pushed (a bug: logged with its traceback).
        self.push_errors = 0
        self._server: Server | None = None
        self._gateway: GatewayView | None = None
        self._calls: Calls | None = None
        self._users = Users(config.users)
        self._defences = Defences(config, self._users)
        #: The DER bytes of every trusted client certificate (``trusted_clients``).
        self._trusted: set[bytes] = set()
        #: Each open session's number (its connection-scoped leases' connection).
        self._session_keys: dict[int, int] = {}
        self._keys = itertools.count(1)
        self._drives: dict[tuple[str, int], DriveNodes] = {}
        self._lines: list[LineNodes] = []
        #: Writable parameter variables: node -> (its drive, the parameter's code).
        self._writable: dict[ua.NodeId, tuple[DriveNodes, str]] = {}
        #: Every drive variable's binding (its name is the audit log's), by node; those
        #: watched by a monitored item.
        self._bound: dict[ua.NodeId, Binding] = {}
        self._watched: dict[ua.NodeId, Binding] = {}
        self._outbox: dict[ua.NodeId, ua.DataValue] = {}
        self._wake = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._counters = LineCounters()
        self._loop: asyncio.AbstractEventLoop | None = None
        #: The node table making drive nodes when asked (None: every node made at start).
        self._table: LazyNodes | None = None
        #: Each method node's handler, bound when its node is made (lazy only).
        self._handlers: dict[ua.NodeId, Any] = {}
        #: Drive nodes made when asked for (._lazy), where the speedups were tested.
        self._lazy = SPEEDUPS_ENABLED
        #: Lazy: the prototype of each drive shape served (._relines).
        self._shapes: dict[object, Shape] = {}
        self._lines_folder: ua.NodeId | None = None
        #: Each trip record as an event (._trip_events), None when none are kept.
        self._trip_events: TripEvents | None = None

    # -- the northbound --------------------------------------------------------------

    def reconfigure(self, config: object) -> list[str]:
        """A reload changed ``[opcua]``: its users (a session whose user was removed, or
        whose password changed, reads on as anonymous) and its session and login limits
        from the next request; the keys it cannot take live are returned."""
        assert isinstance(config, OpcuaConfig)
        old = self.config
        kept = [
            f"opcua.{f.name}"
            for f in dataclasses.fields(config)
            if f.name not in _LIVE_KEYS and getattr(old, f.name) != getattr(config, f.name)
        ]
        self._users.replace(config.users)
        self._defences.retune(config)
        self.config = dataclasses.replace(old, **{key: getattr(config, key) for key in _LIVE_KEYS})
        return kept

    async def start(self, gateway: GatewayView) -> None:
        began = time.perf_counter()
        self._gateway = gateway
        self._loop = asyncio.get_running_loop()
        self._calls = Calls(gateway)
        config = self.config
        try:
            self.certificate = await asyncio.to_thread(
                load_or_generate,
                config.certificate,
                config.private_key,
                f"urn:sj300-async:{gateway.config.gateway_id}",
            )
        except (OSError, ValueError) as exc:
            raise certificate_error(config.certificate, exc) from None
        server = await initialised(
            functools.partial(Server, user_manager=self._users), self.config.nodeset_cache
        )
        self._server = server
        try:
            await self._configure(server, gateway)
            await self._build(server, gateway)
            await self._listen(server)
        except BaseException:
            with contextlib.suppress(Exception):
                await server.stop()
            self._server = None
            raise
        loop = asyncio.get_running_loop()
        self._tasks = [
            loop.create_task(self._push(), name="opcua push"),
            loop.create_task(self._tick(), name="opcua tick"),
        ]
        if self._trip_events is not None:
            self._tasks.append(loop.create_task(self._trip_events.run(), name="opcua trips"))
        self.startup_s = time.perf_counter() - began

    async def _configure(self, server: Server, gateway: GatewayView) -> None:
        config = self.config
        certificate = self.certificate
        assert certificate is not None
        server.set_server_name(f"sj300 gateway {gateway.config.gateway_id}")
        await server.set_application_uri(certificate.application_uri)
        server.product_uri = "urn:sj300-async"
        await server.load_certificate(str(certificate.certificate))
        await server.load_private_key(str(certificate.private_key))
        # Until each endpoint's own ruleset is in place, every channel counts as
        # unencrypted: a request in that moment can read, never write.
        server.set_security_policy(
            [_POLICIES[mode] for mode in config.security],
            permission_ruleset=ChannelRules(ua.MessageSecurityMode.None_, self._users),
        )
        tokens: list[type] = [ua.AnonymousIdentityToken]
        if config.users:
            tokens.append(ua.UserNameIdentityToken)
        server.set_identity_tokens(tokens)
        server.iserver.max_connections = config.max_connections
        # asyncua's defaults take 100 MB requests and 500 queued messages per connection:
        # our largest request (monitored items for every variable) is far below 4 MiB.
        server.limits = TransportLimits(
            max_chunk_count=MAX_MESSAGE_BYTES // 65535 + 1, max_message_size=MAX_MESSAGE_BYTES
        )
        server.iserver.max_pending_messages_per_connection = MAX_PENDING_MESSAGES
        if config.trusted_clients is not None:
            self._trusted = await asyncio.to_thread(load_trusted, config.trusted_clients)

            async def validate(cert: x509.Certificate, description: Any) -> None:
                if not self._admit(uacrypto.der_from_x509(cert)):
                    raise ua.uaerrors.BadCertificateUntrusted

            server.set_certificate_validator(validate)
        self.namespace = await server.register_namespace(config.namespace)
        grants = any(line.config.grants for line in gateway.lines)
        if grants and not config.secure:
            _log.warning(
                "opcua: writes need a SignAndEncrypt channel and no endpoint offers one: "
                "nothing can be written over OPC UA (security = %s)",
                list(config.security),
            )

    async def _build(self, server: Server, gateway: GatewayView) -> None:
        space = SpaceBuilder(self.namespace)
        objects = server.nodes.objects.nodeid
        lines = space.object(objects, "Lines", "Lines", "the gateway's RS-485 lines", folder=True)
        self._lines_folder = lines
        gathered = gather_lines(self, space, lines, gateway.lines)
        await space.commit(server.nodes.objects.session)
        if gateway.trip_records is not None:
            self._trip_events = await TripEvents.install(server, self.namespace)
        if self._lazy:
            aspace = server.iserver.aspace
            self._table = LazyNodes.install(aspace, self.namespace, self._bind_node)
        finish_lines(self, server, gathered)
        follow_watchers(server, self._watch)
        route_writes(server, self.namespace, self._write)
        install_speedups()  # where asyncua is a release they were tested with (logged if not)
        self._defences.install(
            server,
            created=self._session_created,
            activated=self._session_activated,
            closed=self._session_closed,
        )
        # After install: it wraps guard_sessions' creation.
        bound_subscriptions(
            server,
            items_per_session=self.config.max_monitored_items_per_session,
            items_per_address=self.config.max_monitored_items_per_address,
        )
        refuse_registration(server)
        await limit_operations(server, self._defences.refuse_operations)

    def _bind_counters(self, server: Server, line_nodes: LineNodes) -> None:
        for name, counter in line_nodes.counters.items():
            server.set_attribute_value_callback(counter, self._counters.reader(line_nodes, name))
            server.set_attribute_value_setter(counter, _keep)

    def _bind_drive(self, server: Server, nodes: DriveNodes) -> None:
        """Serve *nodes*: their values bound, writable parameters and bindings known."""
        self._bind(server, nodes, lazy=self._lazy)
        for node, code in nodes.writable.items():
            self._writable[node] = (nodes, code)
        for binding in nodes.bindings:
            self._bound[binding.node] = binding

    def _unbind_drive(self, nodes: DriveNodes) -> None:
        """Serve *nodes* no more (a reload removed their line)."""
        for binding in nodes.bindings:
            self._bound.pop(binding.node, None)
            self._watched.pop(binding.node, None)
        for node in nodes.writable:
            self._writable.pop(node, None)
        methods = nodes.methods
        if methods is not None:
            for node in (methods.take_control, methods.run, methods.stop, methods.set_frequency):
                self._handlers.pop(node, None)

    async def lines_changed(
        self, added: Sequence[ServedLine], removed: Sequence[ServedLine]
    ) -> None:
        """A reload added or removed lines: the address space follows, on the running
        server (:mod:`._relines`)."""
        server = self._server
        if server is None:
            return
        for line in removed:
            await remove_line(self, server, line.config.name)
        if added:
            await add_lines(self, server, added)

    def _bind(self, server: Server, nodes: DriveNodes, *, lazy: bool) -> None:
        """Bind *nodes* now, or (*lazy*) keep what :meth:`_bind_node` binds a node with
        when it is made. Their values are taken when first read or watched
        (:attr:`Binding.served`)."""
        drive = nodes.drive
        if not lazy:
            for binding in nodes.bindings:
                server.set_attribute_value_callback(binding.node, self._reader(binding, drive))
                server.set_attribute_value_setter(binding.node, _keep)
        calls = self._calls
        methods = nodes.methods
        if methods is None or calls is None:
            return
        for node, handler in (
            (methods.take_control, calls.take_control),
            (methods.run, calls.run),
            (methods.stop, calls.stop),
            (methods.set_frequency, calls.set_frequency),
        ):

            async def call(parent: ua.NodeId, *args: Any, _handler: Any = handler) -> Any:
                if parent != nodes.node:  # the method of another object (Part 4, 5.11.2)
                    calls.count(ua.StatusCodes.BadMethodInvalid)
                    return ua.StatusCode(ua.StatusCodes.BadMethodInvalid)
                return await _handler(drive, args)

            if lazy:
                self._handlers[node] = call
            else:
                server.link_method(server.get_node(node), call)

    def _bind_node(self, node: ua.NodeId, data: NodeData) -> None:
        """Bind a drive's node the lazy address space has just made (see :meth:`_bind`)."""
        binding = self._bound.get(node)
        if binding is not None:
            value = data.attributes[ua.AttributeIds.Value]
            value.value = None  # as asyncua's set_attribute_value_callback leaves it
            value.value_callback = self._reader(binding, binding.owner.drive)
            value.value_setter = _keep
            return
        handler = self._handlers.get(node)
        if handler is not None:
            data.call = handler

    async def _listen(self, server: Server) -> None:
        config = self.config
        port = config.endpoint.port or free_port(config.endpoint.host)
        host = f"[{config.host_text}]" if ":" in config.host_text else config.host_text
        self.url = f"opc.tcp://{host}:{port}"
        server.set_endpoint(self.url)
        try:
            await server.start()
        except OSError as exc:
            raise GatewayStartError.of("opcua", (config.endpoint,), exc) from None
        admit = self._admit if config.trusted_clients is not None else None
        guard_channels(
            server, lambda mode: ChannelRules(mode, self._users), admit, self._defences.discovery
        )

    def announce(self) -> str | None:
        certificate = self.certificate
        modes = ", ".join(self.config.security)
        line = f"opcua on {self.url} ({modes})"
        if certificate is not None:
            made = "generated" if certificate.generated else "certificate"
            line += f"; {made} {certificate.certificate} (SHA-1 {certificate.thumbprint})"
        return line

    def publish(self, served: ServedDrive) -> None:
        snapshot = served.snapshot
        nodes = self._drives.get((snapshot.line, snapshot.node))
        if nodes is None or not nodes.watched or self._server is None:
            return  # unwatched: a read takes the drive's latest served view itself
        now = asyncio.get_running_loop().time()
        online = snapshot.online
        for group in nodes.watched_groups:  # only those read again (the tick ages the rest)
            seen = (group.stamp(snapshot), online)
            if seen == group.seen:
                continue
            group.seen = seen
            # Judged once per group: its values share their read and their deadline.
            until = group.until(served)
            status = group.status(served, now)
            for binding in group.watched:
                binding.take(served, until)
                value_status = status if binding.value is not None else binding.status(now)
                self._stage(binding, value_status)  # pushed at the batch's flush

    def recorded(self, summary: RecordSummary, served: ServedDrive) -> None:
        """A trip record was kept: its event, from the Server object (._trip_events)."""
        nodes = self._drives.get((summary.line, summary.node))
        if nodes is not None and self._trip_events is not None:
            self._trip_events.announce(summary, nodes.node)

    def flush(self) -> None:
        """The gateway's batch is whole: push what it changed to the subscriptions."""
        if self._outbox:
            self._wake.set()

    def metrics(self) -> Iterable[Metric]:
        return server_metrics(self, self._calls, self._trip_events, self._defences)

    async def close(self) -> None:
        tasks, self._tasks = self._tasks, []
        server, self._server = self._server, None
        try:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        finally:
            if server is not None:
                await server.stop()
            self._defences.close()

    # -- what the tests and the benchmark read ---------------------------------------

    @property
    def untrusted(self) -> int:
        """Client certificates refused (not in trusted_clients)."""
        return self._users.refusals["certificate"]

    @property
    def session_count(self) -> int:
        server = self._server
        if server is None:
            return 0
        return session_count(server)

    @property
    def address_space(self) -> AddressSpace | None:
        """asyncua's address space (None: not started)."""
        return None if self._server is None else self._server.iserver.aspace

    @property
    def lazy_nodes(self) -> LazyNodes | None:
        """The node table making drive nodes when asked (None: every node made at start)."""
        return self._table

    @property
    def event_type_nodes(self) -> int:
        """The namespace's nodes of the trip event's type (._trip_events): not a line's."""
        return 0 if self._trip_events is None else self._trip_events.type_nodes

    @property
    def node_count(self) -> int:
        """The nodes of the gateway's namespace serving its lines and drives, made or not."""
        server = self._server
        if server is None:
            return 0
        own = self.event_type_nodes
        if self._table is not None:
            return self._table.served() - own
        return (
            sum(
                1
                for node in server.iserver.aspace.keys()  # noqa: SIM118 - it has no __iter__
                if node.NamespaceIndex == self.namespace
            )
            - own
        )

    # -- values ----------------------------------------------------------------------

    def _reader(self, binding: Binding, drive: GatewayDrive) -> Any:
        def read(node: ua.NodeId, attribute: ua.AttributeIds) -> ua.DataValue:
            assert self._loop is not None
            try:
                binding.take(drive.served)  # the latest, watched or not
                return drive_datavalue(binding, binding.status(self._loop.time()))
            except Exception:  # a bug of ours: this node fails, not the client's whole read
                self.push_errors += 1
                _log.exception("opcua: cannot serve %s", node)
                return ua.DataValue(StatusCode=ua.StatusCode(ua.StatusCodes.BadInternalError))

        return read

    def _stage(self, binding: Binding, status: int) -> bool:
        """Leave *binding*'s value in the outbox when it or its *status* changed.

        Only for a value some monitored item watches (the callers check).
        """
        shown = (binding.value, status)
        if shown == binding.pushed:
            return False
        try:
            self._outbox[binding.node] = drive_datavalue(binding, status)
        except Exception:  # a bug of ours: logged; the value is tried again next time
            self.push_errors += 1
            _log.exception("opcua: cannot push %s", binding.node)
            return False
        binding.pushed = shown
        return True

    async def _push(self) -> None:
        server = self._server
        assert server is not None
        while True:
            await self._wake.wait()  # the gateway's batch did the gathering: no timer here
            self._wake.clear()
            outbox, self._outbox = self._outbox, {}
            for node, value in outbox.items():
                try:
                    # asyncua's write without its coroutines, where that is the same.
                    if not push_frozen(server, node, value):
                        await server.write_attribute_value(node, value)
                except Exception:  # one bad value must not stop every subscription
                    self.push_errors += 1
                    _log.exception("opcua: cannot push %s to its subscriptions", node)
            self.pushed += len(outbox)

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(TICK_S)
            try:
                self._tick_once()
            except Exception:  # a bug of ours must not end the ticks: logged, tried again
                self.push_errors += 1
                _log.exception("opcua: a tick failed")

    def _tick_once(self) -> None:
        assert self._loop is not None
        now = self._loop.time()
        changed = False
        for binding in self._watched.values():
            pushed = binding.pushed
            # Between samples only time changes a pushed value's status, and time only
            # ages a Good one, past its group's served deadline: the rest are left as they
            # are (a tick visits every watched value, 2,048 a second at plant scale).
            if pushed is not None and (pushed[1] != GOOD or now <= binding.until):
                continue
            changed |= self._stage(binding, binding.status(now))
        for line in self._lines:
            changed |= self._counters.tick(line, now, self._outbox)
        if changed:
            self._wake.set()

    # -- writes and sessions ---------------------------------------------------------

    async def _write(self, value: ua.WriteValue, user: Any) -> ua.StatusCode:
        writable = self._writable.get(value.NodeId)
        if writable is not None:
            nodes, code = writable
            if value.AttributeId != ua.AttributeIds.Value or value.IndexRange:
                return ua.StatusCode(ua.StatusCodes.BadWriteNotSupported)
            assert self._calls is not None
            written = value.Value if value.Value is not None else ua.DataValue()
            return ua.StatusCode(await self._calls.write_parameter(nodes.drive, code, written))
        assert self._calls is not None
        binding = self._bound.get(value.NodeId)
        if binding is not None:  # a drive's read-only variable: a refused write, audited
            return ua.StatusCode(self._calls.not_writable(binding.owner.drive, binding.name))
        known = self._server is not None and value.NodeId in self._server.iserver.aspace
        status = ua.StatusCodes.BadNotWritable if known else ua.StatusCodes.BadNodeIdUnknown
        self._calls.count(status)
        _log.debug("opcua: a write to %s refused: %s", value.NodeId, ua.StatusCode(status).name)
        return ua.StatusCode(status)

    def _admit(self, certificate: bytes | None) -> bool:
        """True when *certificate* (DER) is one of ``trusted_clients`` (counted when not)."""
        if certificate is not None and certificate in self._trusted:
            return True
        self._defences.refuse_certificate()
        _log.info("opcua: refused a client certificate not in trusted_clients")
        return False

    def _session_created(self, session: Any) -> None:
        self._session_keys[id(session)] = next(self._keys)

    def _session_activated(self, session: Any) -> None:
        """The session's user names the session: its lease's connection (re-activation too)."""
        user = session.user
        if isinstance(user, Principal):
            user.key = self._session_keys.get(id(session), 0)

    def _watch(self, node: ua.NodeId, change: int) -> None:
        """A monitored item added to (+1) or deleted from (-1) *node*'s value."""
        binding = self._bound.get(node)
        if binding is None:  # a line counter, or a node not ours
            self._counters.watch(node, change)
            return
        nodes = binding.owner
        binding.watched += change
        nodes.watched += change
        nodes.follow()
        if binding.watched > 0:
            self._watched[node] = binding
            return
        # Nobody watches it now: what it showed is forgotten. A subscription made
        # later starts from a read, and a first push of the same value notifies
        # nothing (asyncua compares value and status).
        self._watched.pop(node, None)
        binding.pushed = None

    def _session_closed(self, session: Any) -> None:
        key = self._session_keys.pop(id(session), None)
        if key is not None and self._gateway is not None:
            self._gateway.disconnected(Principal(key=key).connection)


def _keep(node: NodeData, attribute: ua.AttributeIds, value: ua.DataValue) -> None:
    """The value setter of a drive's variable: its binding holds the value, not asyncua."""
