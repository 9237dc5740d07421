"""The gateway as a Sparkplug B 3.0 edge node: births, data by exception, deaths, commands.

:class:`EdgeNode` is the ``[sparkplug]`` northbound (:mod:`._config`; the
deprecated ``[mqtt] sparkplug = true`` too). Its edge node id is the gateway's id; each
drive is a device (:mod:`._device`). Topics are
``spBv1.0/<group_id>/<TYPE>/<gateway id>[/<device id>]``.

The session (Sparkplug 3.0, sections 5.4 to 5.7):

- Each connection attempt takes the next ``bdSeq`` (0 at the process's
  start, 0..255, wrapping) and registers the NDEATH that carries it as the
  last will (QoS 1, not retained), on a connection of its own
  (``<client id>-spb``, clean session).
- It subscribes to its NCMD and DCMD topics (QoS 1), and with a
  ``primary_host_id`` to ``spBv1.0/STATE/<host>`` first. One the broker
  refuses (an ACL) is said, counted and shown on /healthz, and the session
  goes on (the MQTT transport's ``Subscriptions``: a refused STATE leaves the
  node unborn, waiting, which /healthz then explains). With a primary
  host, nothing is born until the host's retained STATE says
  ``online: true``; a STATE with ``online: false`` newer than the last one
  seen (its ``timestamp``), while born, makes the edge node publish its
  NDEATH and disconnect, then reconnect (the next ``bdSeq``) and wait
  again. The lease the Sparkplug client holds on a drive of a
  ``lease_scope = "connection"`` line lapses when the host goes offline or
  the connection is lost.
- NBIRTH (``seq`` 0): ``bdSeq``, ``Node Control/Rebirth`` (false; no
  alias) and the gateway's metrics (:mod:`._node_metrics`), then a
  DBIRTH for each drive the poller hears. NDATA carries the gateway's
  metrics that changed, checked once a second.
- A drive's sample is a DDATA of the metrics whose value changed since the
  device's last message (report by exception: a sample that changed
  nothing sends nothing); DDEATH when the poller takes the drive offline,
  and a new DBIRTH with every value when it comes back. The values are the
  drive as the gateway serves it at the sample (what is fresh and what is
  null is decided there, once for every northbound), read from the same
  state message as the JSON topics'; ``Control/Lease`` is the served lease
  when the message goes out.
- ``seq`` counts every message after NBIRTH, 0..255 and wrapping; a
  payload's timestamp is the sample's time (the birth of the edge node's
  own metrics: now), and so is each metric's.
- NCMD ``Node Control/Rebirth = true``: NBIRTH and every DBIRTH again, with
  the same ``bdSeq`` (no death first).
- A clean stop publishes the NDEATH, then disconnects.

Never blocking the poller: :meth:`EdgeNode.publish` keeps the drive's
latest sample and marks it; the edge node's task turns samples into
messages in order. A sample replaced before its turn is counted
(``samples_replaced``); its changes go out with the newer one, since a
DDATA is the difference from what the host last got.

Commands (DCMD): :mod:`._commands` judges a metric, :mod:`._workers`
carries the writes out, each drive's in order, and tells what is refused;
the primary host's STATE is read by :mod:`._host`. Input that changes
nothing is counted by reason (:data:`~._stats.BAD_INPUTS`) and logged at
DEBUG with an escaped excerpt.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Final

from .. import (
    GatewayDrive,
    GatewayView,
    ServedDrive,
    ServedLine,
    excerpt,
)
from ..mqttlink import Subscriptions, cancel_and_wait, keep_connected, new_client, reader
from ..mqttlink.client import Client, MqttError, Will
from ._config import SparkplugConfig
from ._device import Device, DeviceFlags
from ._host import PrimaryHost, Unread
from ._node_metrics import (
    REBIRTH,
    SESSION_METRICS,
    node_definitions,
    node_values,
)
from ._payload import (
    MalformedPayload,
    MetricDef,
    decode_payload,
    encode_payload,
)
from ._stats import SparkplugStats, sparkplug_families
from ._workers import CLIENT, MAX_COMMAND_BYTES, DeviceCommands

if TYPE_CHECKING:
    from prometheus_client.core import Metric

    from ..recorder import RecordSummary

__all__ = ["NAMESPACE", "EdgeNode"]

_log = logging.getLogger("sj300_async.gateway.sparkplug")

NAMESPACE: Final = "spBv1.0"
BACKOFF_MAX_S: Final = 30.0
#: How often the gateway's own metrics are checked for an NDATA.
NODE_TICK_S: Final = 1.0
CLOSE_TIMEOUT_S: Final = 3.0
#: Messages published between two yields to the event loop: publishing at QoS 0
#: never waits while the socket takes the bytes, and a burst of births for a
#: plant's drives must not hold the polls up meanwhile.
YIELD_EVERY: Final = 64
#: After the primary host's death, the next NBIRTH waits this long after the last:
#: anyone may publish a STATE, and a flapping one was a death and a rebirth each.
HOST_REBIRTH_MIN_S: Final = 10.0

Key = tuple[str, int]


class _HostOffline(MqttError):
    """The primary host went offline: the session ends (reconnect, wait for it again)."""


class EdgeNode:
    """The gateway's Sparkplug edge node (see the module docstring); a northbound."""

    def __init__(self, config: SparkplugConfig) -> None:
        self.config = config
        self.stats = SparkplugStats()
        self._subscriptions = Subscriptions(self.stats, _log, "Sparkplug")
        self.edge_node = ""
        self._gateway: GatewayView | None = None
        self._devices: dict[Key, Device] = {}
        self._by_id: dict[str, Device] = {}
        #: Devices made so far (each new one's ordinal), and those a reload removed whose
        #: DDEATH is not sent yet.
        self._ordinals = 0
        self._gone: list[Device] = []
        self._node_defs: list[MetricDef] = []
        #: The latest sample of each drive, as served (its values at the sample; who
        #: holds the lease, when the message goes out).
        self._latest: dict[Key, ServedDrive] = {}
        #: Each device's latest trip record: its code and id (Trip Record/*).
        self._records: dict[Key, tuple[str | None, str]] = {}
        #: Drives with a sample not yet turned into a message, in arrival order.
        self._dirty: dict[Key, None] = {}
        #: What the host was last told of each live device (its values, in metric order).
        self._alive: dict[Key, list[object]] = {}
        self._node_values: list[object] = []
        self._wake = asyncio.Event()
        self._bdseq = -1  # the current connection's (its will's)
        self._next_bdseq = 0
        self._seq = 0
        self._born = False
        self._rebirth = False
        #: Loop time of the last NBIRTH; the window births wait for after a host's death.
        self._nbirth_at = -math.inf
        self._births_after = -math.inf
        self.host_rebirth_s = HOST_REBIRTH_MIN_S
        host = config.primary_host_id
        #: The primary host, whose STATE the edge node waits for (None: no host).
        self._host = None if host is None else PrimaryHost(host, NAMESPACE)
        self._client: Client | None = None
        self._epoch = 0
        self._session_name: str | None = None
        self._commands = DeviceCommands(self, self.stats, self._by_id)
        self._task: asyncio.Task[None] | None = None
        self._closing = False

    # -- topics ------------------------------------------------------------------------

    def topic(self, kind: str, device: str | None = None) -> str:
        base = f"{NAMESPACE}/{self.config.group_id}/{kind}/{self.edge_node}"
        return base if device is None else f"{base}/{device}"

    @property
    def host_online(self) -> bool | None:
        """The primary host's latest word on this connection (None: none, or no host)."""
        return None if self._host is None else self._host.online

    @property
    def born(self) -> bool:
        return self._born

    # -- what the command workers see (._workers.CommandSession) -------------------------

    @property
    def gateway(self) -> GatewayView | None:
        return self._gateway

    @property
    def epoch(self) -> int:
        return self._epoch

    @property
    def session_name(self) -> str | None:
        return self._session_name

    def alive(self, key: Key) -> bool:
        return key in self._alive

    def refusal_changed(self, device: Device) -> None:
        key = device.drive.key
        latest = self._latest.get(key)
        if latest is not None and device.writable:
            self._mark(key, latest, sample=False)  # the next DDATA tells it

    def bad(self, reason: str, text: str) -> None:
        self.stats.bad_input[reason] += 1
        _log.debug("Sparkplug: %s: %s", reason, text)

    @property
    def bdseq(self) -> int:
        """The bdSeq of the current (or last) connection; -1 before the first."""
        return self._bdseq

    # -- the northbound ----------------------------------------------------------------

    async def start(self, gateway: GatewayView) -> None:
        self._gateway = gateway
        self.edge_node = gateway.config.gateway_id
        self._add_devices(gateway.drives)
        self._node_defs = node_definitions(gateway.lines)
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="sparkplug")

    def _add_devices(self, drives: Iterable[GatewayDrive]) -> None:
        """Devices for *drives*, their ordinals (so their aliases) after every one so far."""
        for drive in drives:
            self._ordinals += 1
            trips = self._gateway is not None and self._gateway.trip_records is not None
            device = Device(drive, self._ordinals, trips=trips)
            self._devices[drive.key] = device
            self._by_id[device.id] = device

    async def lines_changed(
        self, added: Sequence[ServedLine], removed: Sequence[ServedLine]
    ) -> None:
        """A reload added or removed lines: a DDEATH for each removed device the host
        knows, then NBIRTH (the node's metrics name the lines) and every DBIRTH again on
        the same session; the devices kept keep their aliases."""
        for line in removed:
            for node in line.drives:
                device = self._devices.pop((line.config.name, node), None)
                self._records.pop((line.config.name, node), None)
                if device is not None:
                    del self._by_id[device.id]
                    self._gone.append(device)
        self._add_devices(drive for line in added for drive in line.drives.values())
        assert self._gateway is not None
        self._node_defs = node_definitions(self._gateway.lines)
        self._rebirth = True
        self._wake.set()

    def _deaths(self) -> Iterator[tuple[str, bytes]]:
        """A DDEATH for each removed device the host was told is alive."""
        gone, self._gone = self._gone, []
        for device in gone:
            key = device.drive.key
            self._latest.pop(key, None)
            self._dirty.pop(key, None)
            if self._alive.pop(key, None) is not None:
                self.stats.published["DDEATH"] += 1
                stamp = int(time.time() * 1000)
                payload = encode_payload(stamp, self._next_seq(), (), birth=False)
                yield self.topic("DDEATH", device.id), payload

    def announce(self) -> str | None:
        host = self.config.primary_host_id
        waits = f", primary host {host}" if host is not None else ""
        return f"sparkplug to {self.config.url} as {self.topic('NBIRTH')}{waits}"

    def publish(self, served: ServedDrive) -> None:
        """A drive's new sample: kept, and marked for the edge node's task (never blocks)."""
        if self._closing:
            return
        snapshot = served.snapshot
        key = (snapshot.line, snapshot.node)
        if key not in self._devices:
            return
        self.stats.samples += 1
        self._mark(key, served)

    def _mark(self, key: Key, served: ServedDrive, *, sample: bool = True) -> None:
        if key in self._dirty and sample:
            self.stats.replaced += 1
        self._latest[key] = served
        self._dirty[key] = None
        if not sample:  # a sample goes out at the batch's flush
            self._wake.set()

    def recorded(self, summary: RecordSummary, served: ServedDrive) -> None:
        """A trip record was kept: its code and id go out in the device's next DDATA."""
        key = (summary.line, summary.node)
        if key in self._devices and not self._closing:
            self._records[key] = (summary.code, summary.id)
            self._mark(key, self._latest.get(key, served), sample=False)

    def flush(self) -> None:
        """The gateway's batch is whole: send the devices it changed."""
        if self._dirty:
            self._wake.set()

    def metrics(self) -> Iterator[Metric]:
        return sparkplug_families(self.stats, born=self._born, host_online=self.host_online)

    def problems(self) -> list[str]:
        """Subscriptions the broker refused (the northbound's optional hook, for /healthz)."""
        return self._subscriptions.problems()

    # -- payloads ----------------------------------------------------------------------

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (seq + 1) % 256
        return seq

    def _ndeath(self) -> bytes:
        return encode_payload(
            int(time.time() * 1000), None, [(self._node_defs[0], self._bdseq)], birth=True
        )

    def _node_now(self) -> list[object]:
        assert self._gateway is not None
        return node_values(self._bdseq, self._gateway.lines)

    def _device_values(self, device: Device, served: ServedDrive) -> list[object]:
        """The device's metrics: the values served at the sample, the lease as it is now."""
        lease = served.lease_holder(asyncio.get_running_loop().time()) == CLIENT
        flags = DeviceFlags(lease=lease, lapse_pending=served.lapse_pending)
        key = device.drive.key
        refusal = self._commands.refusals.get(key)
        return device.values(served.values(), flags, refusal, self._records.get(key))

    # -- turning samples into messages (the edge node's task) -----------------------------

    def _births(self) -> Iterator[tuple[str, bytes]]:
        """NBIRTH (seq 0), then a DBIRTH for each drive heard now."""
        self._seq = 0
        self._node_values = self._node_now()
        stamp = int(time.time() * 1000)
        nbirth = encode_payload(
            stamp, self._next_seq(), zip(self._node_defs, self._node_values, strict=True),
            birth=True,
        )  # fmt: skip
        # Born from here on (the publisher sends nothing once not born: a death came).
        self._alive.clear()
        self._born, self._rebirth = True, False
        self._nbirth_at = asyncio.get_running_loop().time()
        self.stats.published["NBIRTH"] += 1
        yield self.topic("NBIRTH"), nbirth
        for key in self._devices:
            if self._rebirth:
                return  # asked again meanwhile: the next turn starts over
            self._dirty.pop(key, None)
            latest = self._latest.get(key)
            if latest is not None and latest.values().online:
                yield self._dbirth(key, latest)

    def _dbirth(self, key: Key, served: ServedDrive) -> tuple[str, bytes]:
        device = self._devices[key]
        values = self._device_values(device, served)
        self._alive[key] = values
        self.stats.published["DBIRTH"] += 1
        return self.topic("DBIRTH", device.id), encode_payload(
            int(served.snapshot.time * 1000),
            self._next_seq(),
            zip(device.definitions, values, strict=True),
            birth=True,
            alias_base=device.alias_base,
        )

    def _device_message(self, key: Key) -> tuple[str, bytes] | None:
        """What the latest sample of *key* changes for the host: a message or nothing."""
        served = self._latest[key]
        online = served.values().online
        device = self._devices[key]
        last = self._alive.get(key)
        if last is None:
            return self._dbirth(key, served) if online else None
        stamp = int(served.snapshot.time * 1000)
        if not online:
            del self._alive[key]
            self.stats.published["DDEATH"] += 1
            return self.topic("DDEATH", device.id), encode_payload(
                stamp, self._next_seq(), (), birth=False
            )
        values = self._device_values(device, served)
        defs = device.definitions
        changed = [(defs[i], v) for i, v in enumerate(values) if v != last[i]]
        if not changed:
            return None
        self._alive[key] = values
        self.stats.published["DDATA"] += 1
        return self.topic("DDATA", device.id), encode_payload(
            stamp, self._next_seq(), changed, birth=False, alias_base=device.alias_base
        )

    def _node_data(self) -> tuple[str, bytes] | None:
        values = self._node_now()
        changed = [
            (self._node_defs[i], v)
            for i, v in enumerate(values)
            if i >= SESSION_METRICS and v != self._node_values[i]
        ]
        if not changed:
            return None
        self._node_values = values
        self.stats.published["NDATA"] += 1
        return self.topic("NDATA"), encode_payload(
            int(time.time() * 1000), self._next_seq(), changed, birth=False
        )

    def _ready(self) -> bool:
        """Connected, and the primary host (if any) is online: messages may go out."""
        if self._client is None:
            return False
        return self._host is None or self._host.online is True

    def _outgoing(self) -> Iterator[tuple[str, bytes]]:
        """Everything due now, in order (each with its seq already taken)."""
        if self._born:
            yield from self._deaths()
        if not self._born or self._rebirth:
            yield from self._births()
        while self._dirty and not self._rebirth:
            key = next(iter(self._dirty))
            del self._dirty[key]
            message = self._device_message(key)
            if message is not None:
                yield message

    async def _publisher(self, client: Client) -> None:
        while True:
            await self._wake.wait()  # the gateway's batch did the gathering: no timer here
            self._wake.clear()
            wait = self._births_after - asyncio.get_running_loop().time()
            if not self._born and wait > 0:
                await asyncio.sleep(wait)  # a flapping host: births at the window's end
            if not self._ready():
                continue
            for sent, (topic, payload) in enumerate(self._outgoing(), 1):
                if not self._born:
                    break  # dead meanwhile (the host went offline): nothing after the NDEATH
                await self._send(client, topic, payload)
                if not sent % YIELD_EVERY:
                    await asyncio.sleep(0)

    async def _ticker(self, client: Client) -> None:
        while True:
            await asyncio.sleep(NODE_TICK_S)
            if self._born and self._ready() and not self._rebirth:
                message = self._node_data()
                if message is not None:
                    await self._send(client, *message)

    async def _send(self, client: Client, topic: str, payload: bytes) -> None:
        try:
            await client.publish(topic, payload, qos=0, retain=False)
        except BaseException:
            self.stats.lost += 1
            raise

    # -- the connection ------------------------------------------------------------------

    def _make_client(self) -> Client:
        """A client for the next connection attempt: the next bdSeq, in its will."""
        self._bdseq = self._next_bdseq
        self._next_bdseq = (self._bdseq + 1) % 256
        return new_client(
            self.config,
            identifier=self.config.client_id,
            will=Will(self.topic("NDEATH"), self._ndeath(), qos=1, retain=False),
            max_payload=MAX_COMMAND_BYTES,
        )

    async def _run(self) -> None:
        await keep_connected(
            self._make_client,
            self._connection,
            url=self.config.url,
            log=_log,
            ceiling_s=BACKOFF_MAX_S,
            stats=self.stats,
            who=f" as Sparkplug edge node {self.config.group_id}/{self.edge_node}",
        )

    async def _connection(self, client: Client, connected: Callable[[], None]) -> None:
        host = self._host
        self._born = False
        if host is not None:
            # The host's word counts on the connection it came on: a broker that
            # restarted empty may hold no STATE at all (the stamp stays, to order).
            host.forget()
        self._epoch += 1
        self._session_name = f"sparkplug session {self._epoch}"
        # Read while subscribing: a flood on NCMD ahead of DCMD's SUBACK hung it (reader).
        receiver = reader(self._receiver(client), "sparkplug receiver")
        try:
            subscribe = self._subscriptions.subscribe  # a refusal: said, counted, a problem
            if host is not None:
                await subscribe(client, host.topic, qos=1, unheard="the primary host's STATE")
            await subscribe(client, self.topic("NCMD"), qos=1, unheard="node commands (NCMD)")
            await subscribe(
                client, self.topic("DCMD", "+"), qos=1, unheard="device commands (DCMD)"
            )
            self._client = client
            connected()
            self._wake.set()
            await self._session(client, receiver)
        except asyncio.CancelledError:
            if self._closing and self._born:
                await self._say_dead(client)
            raise
        except Exception:
            # The session ends on an error the connection may outlive (a publish that
            # timed out, a bug of ours): the disconnect that follows is clean, which
            # drops the will, so the host hears the death now (a lost connection
            # fails this at once, and its will speaks instead).
            if self._born:
                await self._say_dead(client, lost_is_expected=True)
            raise
        finally:
            receiver.cancel()  # (awaited by the session, when there was one)
            self._client = None
            self._born = False
            self._end_session()

    def _end_session(self) -> None:
        """The Sparkplug session is over: commands of it are stale, its leases lapse."""
        self._alive.clear()  # for the host, every device died with the session
        self._epoch += 1
        session, self._session_name = self._session_name, None
        if session is not None and self._gateway is not None:
            self._gateway.disconnected(session)

    async def _say_dead(self, client: Client, *, lost_is_expected: bool = False) -> None:
        """NDEATH before a disconnect we choose (a clean disconnect drops the will).

        *lost_is_expected*: the session ended on an error, most often the lost
        connection, where the will speaks: a failure is no news (DEBUG).
        """
        try:
            async with asyncio.timeout(CLOSE_TIMEOUT_S):
                await client.publish(self.topic("NDEATH"), self._ndeath(), qos=1, retain=False)
            self.stats.published["NDEATH"] += 1
        except (MqttError, TimeoutError) as exc:
            level = logging.DEBUG if lost_is_expected else logging.WARNING
            _log.log(level, "Sparkplug: could not publish NDEATH: %s", exc or "time-out")

    async def _session(self, client: Client, receiver: asyncio.Task[None]) -> None:
        tasks = {
            asyncio.create_task(self._publisher(client), name="sparkplug publisher"),
            receiver,
            asyncio.create_task(self._ticker(client), name="sparkplug ticker"),
        }
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            await cancel_and_wait(tasks)
        for task in done:
            task.result()
        raise MqttError("the session ended")

    async def _receiver(self, client: Client) -> None:
        async for message in client.messages:
            topic, payload, length = message.topic, message.payload, message.length
            if self._host is not None and topic == self._host.topic:
                if self._host_state(payload, length):
                    self.stats.host_offline += 1
                    _log.warning(
                        "Sparkplug: primary host %s went offline: NDEATH, reconnecting",
                        self.config.primary_host_id,
                    )
                    await self._say_dead(client)
                    self._births_after = self._nbirth_at + self.host_rebirth_s
                    raise _HostOffline(f"primary host {self.config.primary_host_id} offline")
                continue
            self.stats.commands += 1
            if topic == self.topic("NCMD"):
                self._node_command(payload, length, retained=message.retain)
            else:
                self._commands.receive(topic, payload, length, retained=message.retain)

    # -- the primary host ----------------------------------------------------------------

    def _host_state(self, payload: bytes, length: int) -> bool:
        """Take a STATE message; True when it means: die now (the host went offline)."""
        assert self._host is not None
        word = self._host.read(payload, length)
        if isinstance(word, Unread):
            self.bad(word.reason, word.text)
            return False
        if word.online:
            if not word.again:
                _log.info("Sparkplug: primary host %s is online", self._host.id)
            self._wake.set()
            return False
        self._end_session()  # the host's leases lapse with it
        self._epoch += 1
        self._session_name = f"sparkplug session {self._epoch}"
        die, self._born = self._born, False  # nothing is published after the NDEATH
        return die

    # -- commands ------------------------------------------------------------------------

    def _node_command(self, payload: bytes, length: int, *, retained: bool) -> None:
        if self._commands.unread("NCMD", length, retained=retained) is not None:
            return
        try:
            decoded = decode_payload(payload)
        except MalformedPayload as exc:
            self.bad("malformed", f"NCMD {excerpt(payload)!r}: {exc}")
            return
        for metric in decoded.metrics:
            if metric.name != REBIRTH:
                self.bad("unknown_metric", f"NCMD {excerpt(metric.label)}")
            elif metric.member != "boolean_value" or metric.is_null:
                self.bad("wrong_type", f"NCMD {REBIRTH} takes a Boolean")
            elif metric.value is True:
                self.stats.rebirths += 1
                _log.info("Sparkplug: rebirth requested")
                self._rebirth = True
                self._wake.set()

    # -- stopping ------------------------------------------------------------------------

    async def close(self) -> None:
        """Stop: NDEATH, then disconnect (the commands waiting are not carried out)."""
        if self._task is None:
            return
        self._closing = True
        self._epoch += 1
        await self._commands.close()
        task, self._task = self._task, None
        # Its NDEATH and disconnect take up to CLOSE_TIMEOUT_S and the client's close.
        await cancel_and_wait({task}, patience_s=2 * CLOSE_TIMEOUT_S)
