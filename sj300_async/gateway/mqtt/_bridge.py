"""The gateway on MQTT: each drive's state and availability, Home Assistant discovery, commands.

:class:`MqttBridge` is the MQTT northbound, started by the gateway when the
configuration has ``[mqtt]``. It publishes what :mod:`._topics` (the
contract, shared with the fleet subscriber) lays out:

- ``<prefix>/<gw>/availability``: ``online`` (retained) once connected; the
  last will says ``offline`` when the broker loses the gateway (a crash: at
  once; a frozen process, a cut cable: 1.5 ``keepalive_s`` later, plus the broker's
  check interval); a clean stop says ``offline`` itself: the drives are not served.
- ``…/<line>/<node>/state``: one retained :class:`~._topics.StateMessage`
  per drive snapshot (every poll, and every write's read-back): the drive
  as the gateway serves it, what is fresh and what is null decided there,
  not here (:mod:`._messages`).
- ``…/<line>/<node>/availability``: ``online`` while the poller hears the
  drive (and it has answered at least once), published when that changes.
- Home Assistant discovery (``discovery = true``, :mod:`._discovery`).
- ``…/<line>/<node>/set/<what>``: commands (:mod:`._commands`), judged and
  carried out by the gateway like every door's writes. A refusal is
  answered on ``…/<line>/<node>/error`` (JSON, not retained: the topic, an
  excerpt of the payload, the neutral ``reason`` and a sentence).

Decisions:

- **One identity for MQTT.** MQTT carries no client identity a gateway can
  trust, so every command comes from client ``"mqtt"``: whoever may publish
  to the ``set`` topics (the broker's ACL decides) shares one control lease,
  and a Modbus client holding a drive's lease makes MQTT commands to it
  refused (lease held), and the other way round.
- **Never a stale command.** A message with the retain flag is refused: the
  broker stored it, nobody sent it now (a retained "run_forward" would
  start a motor at every reconnect). Commands are taken only while
  connected, with a clean session (nothing queued for the gateway while it
  was away); one received but not started before the connection broke is
  discarded, counted, never carried out later.
- **A client's bytes are untrusted.** A payload longer than
  ``MAX_PAYLOAD_BYTES`` (4 KiB) is refused unread (``malformed``, counted
  in ``BridgeStats.oversized``) and never queued; what a client sent (the
  payload, the end of the topic) reaches the error reply, the log and the
  audit log only as a short escaped excerpt (:func:`~sj300_async.gateway.excerpt`).
- **A flood costs a lookup per message** (:mod:`._intake`): each command
  spends from a budget per drive and in all before its payload is read;
  past it, it is dropped unread (counted ``throttled``: no reply, no
  audit, one log line now and then). Error replies have a budget too
  (past it counted in ``errors_dropped``): junk must not become a flood
  of publishes back through the broker.
  Messages are read from the connection's first moment, its set-up
  included: the broker's answers the set-up waits for come behind them.
- **Never block the poller.** :meth:`MqttBridge.publish` only builds the
  message and leaves it in the outbox, which holds at most one state and
  one availability per drive: a newer one replaces the one not sent yet
  (counted in ``BridgeStats.replaced``), so a broker that is down or slow
  costs memory bounded by the number of drives, and the state that reaches
  it is always the latest. The bridge's task drains the outbox.
- **Reconnecting** (:mod:`sj300_async.gateway.mqttlink`): back off 0.5 s doubling to
  30 s, then republish availability, discovery and every drive's latest state
  (the broker may have restarted without its retained messages).
- Commands to one drive are carried out in order (a lease, then a
  frequency); each drive has its own queue, so a drive that does not
  answer delays only its own commands, never another drive's heartbeat.
  A stop waits behind none: the commands waiting when it comes are dropped
  (refused ``busy``, audited), and it follows the write under way.
- The bridge publishes with the configured QoS and waits for each batch's
  acknowledgements (at most ``MAX_IN_FLIGHT`` at once) before the next: a
  slow broker makes the outbox coalesce, never grow. A broker that never
  acknowledges loses the connection after ``keepalive_s`` (counted by the
  transport, :mod:`sj300_async.gateway.mqttlink`): its will says ``offline``.
- For Home Assistant: events (:mod:`._drive_events`), the lease its presence
  keeps (:mod:`._presence`), an earlier configuration's leftovers cleared (:mod:`._sweep`).
- **Home Assistant's births coalesce** (:mod:`._births`): anyone may publish
  one; a storm of them costs one re-discovery per 10 s, never one each.
- A subscription the broker refuses (an ACL: the commands, Home
  Assistant's status) is said, counted and one of :meth:`MqttBridge.problems`
  (/healthz) until granted (the transport's ``Subscriptions``); the bridge goes on
  publishing.

Nothing is dropped silently: every replaced, lost or discarded message and
every refused command is counted in :attr:`MqttBridge.stats` and logged at
DEBUG (refusals also in the audit log).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import math
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Final

from .. import (
    DROPPED_BY_STOP,
    GatewayDrive,
    GatewayView,
    Refusal,
    ServedDrive,
    ServedLine,
    WriteResult,
    compact_json,
    excerpt,
)
from ..mqttlink import Subscriptions, cancel_and_wait, keep_connected, new_client, reader
from ..mqttlink.client import Client, MqttError, Will
from ._births import Rediscovery
from ._commands import MAX_PAYLOAD_BYTES, error_text, oversized, parse_command
from ._config import MqttConfig
from ._discovery import FrequencyLimits, iter_discovery
from ._drive_events import DriveEvents, refused_event, trip_record_event
from ._intake import CommandIntake
from ._messages import state_payload
from ._outbox import MAX_IN_FLIGHT, Key, Out, Outbox
from ._presence import HomeAssistantLease
from ._stats import BridgeStats, mqtt_families
from ._sweep import Sweeper, sweep_and_say
from ._topics import AVAILABLE, UNAVAILABLE, Topics

if TYPE_CHECKING:
    from prometheus_client.core import Metric

    from ..recorder import RecordSummary

__all__ = ["CLIENT", "MqttBridge"]

_log = logging.getLogger("sj300_async.gateway.mqtt")

#: The client every MQTT command comes from (see the module docstring).
CLIENT: Final = "mqtt"
#: The reconnection back-off's ceiling.
BACKOFF_MAX_S: Final = 30.0
#: Commands waiting for one drive, at most (more are refused: busy).
MAX_COMMANDS: Final = 16
#: How long a clean stop waits for a write under way, and for its last publishes.
CLOSE_TIMEOUT_S: Final = 3.0

_RETAINED: Final = WriteResult(Refusal.NOT_ALLOWED, "a retained command is never carried "
                               "out (publish commands without retain)")  # fmt: skip


class MqttBridge:
    """The gateway's MQTT client (see the module docstring); a northbound."""

    def __init__(self, config: MqttConfig) -> None:
        self.config = config
        self.stats = BridgeStats()
        self._subscriptions = Subscriptions(self.stats, _log, "MQTT")
        self._intake = CommandIntake(_log, commands=config.commands)
        self._events = DriveEvents()
        self._limits = FrequencyLimits()
        self._presence = HomeAssistantLease(CLIENT, enabled=config.home_assistant_lease)
        #: The sweep of what the configuration no longer has (:mod:`._sweep`), until done.
        self._sweeper: Sweeper | None = None
        self._sweep: asyncio.Task[None] | None = None
        self.topics = Topics("", config.prefix)  # the gateway's id is known at start
        self._gateway: GatewayView | None = None
        self._birth = f"{config.discovery_prefix}/status"
        #: Home Assistant's births, coalesced: anyone may publish them (see _births).
        self._rediscovery = Rediscovery(self._announce, self.stats, _log)
        #: Waiting to be published.
        self._outbox = Outbox(self.stats)
        self._wake = asyncio.Event()
        #: Clear while the publisher has a batch on its way: a clean stop waits for it
        #: (cancelled between a PUBLISH and its PUBACK, a message that did reach the
        #: broker would be counted lost).
        self._idle = asyncio.Event()
        self._idle.set()
        #: The latest state message of each drive (republished on every connect).
        self._latest: dict[Key, Out] = {}
        #: The availability last put in the outbox, per drive.
        self._availability: dict[Key, bool] = {}
        self._client: Client | None = None
        #: Changes on every connect and loss: a command of an older epoch is stale.
        self._epoch = 0
        #: The connection's name in the gateway (a connection-scoped lease's holder
        #: connection), None while not connected.
        self._session_name: str | None = None
        self._commands: dict[Key, asyncio.Queue[tuple[int, str, bytes, str]]] = {}
        self._workers: dict[Key, asyncio.Task[None]] = {}
        self._busy: set[Key] = set()
        self._task: asyncio.Task[None] | None = None
        self._closing = False
        #: Loop time by which a closing connection stops flushing and says "offline".
        self._close_by = math.inf

    @property
    def connected(self) -> bool:
        return self._client is not None

    # -- the northbound --------------------------------------------------------------

    async def start(self, gateway: GatewayView) -> None:
        """Connect (and keep reconnecting) in the background."""
        self._gateway = gateway
        self.topics = Topics(gateway.config.gateway_id, self.config.prefix)
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="mqtt bridge")

    def announce(self) -> str | None:
        return f"mqtt to {self.config.url} as {self.topics.gateway}"

    def publish(self, served: ServedDrive) -> None:
        """A drive's new snapshot: publish its state (and availability when it changed).

        Never blocks: the message waits in the outbox (see the module docstring).
        """
        if self._closing:
            return
        payload = state_payload(self.topics.gateway, served)
        snapshot = served.snapshot
        key = (snapshot.line, snapshot.node)
        self.stats.samples[key] += 1
        out = Out(self.topics.state(*key), payload, retain=True, drive=key)
        self._latest[key] = out
        self._put(out, wake=False)  # sent at the batch's flush
        if self.config.discovery and self._limits.changed(served):  # its own maximum now
            for topic, body in self._limits.config(self.config, self.topics, self._drive(*key)):
                self._put(Out(topic, compact_json(body), retain=True), wake=False)
        for event in self._events.on_served(served):
            self._put_error(Out(self.topics.event(*key), json.dumps(event).encode(), False))
        available = snapshot.available
        if self._availability.get(key) != available:
            self._availability[key] = available
            self._put(self._availability_out(key), wake=False)

    def recorded(self, summary: RecordSummary, served: ServedDrive) -> None:
        """A trip record was kept: its message on ``…/trip``, not retained."""
        if not self._closing:
            payload = json.dumps(trip_record_event(summary)).encode()
            self._put_error(Out(self.topics.trip(summary.line, summary.node), payload, False))

    def reconfigure(self, config: object) -> list[str]:
        """A reload changed ``[mqtt]``: the commands' budget from the next command; the
        rest (the broker, topics, discovery) waits for a restart (returned)."""
        assert isinstance(config, MqttConfig)
        kept = [
            f"mqtt.{f.name}"
            for f in dataclasses.fields(config)
            if f.name != "commands" and getattr(self.config, f.name) != getattr(config, f.name)
        ]
        self._intake.retune(config.commands)
        self.config = dataclasses.replace(self.config, commands=config.commands)
        return kept

    def flush(self) -> None:
        """The gateway's batch is whole: send what it left in the outbox."""
        if self._outbox:
            self._wake.set()

    def metrics(self) -> Iterator[Metric]:
        yield from mqtt_families(self.stats)
        yield from self._presence.metrics()

    def problems(self) -> list[str]:
        """Subscriptions the broker refused (the northbound's optional hook, for /healthz)."""
        return self._subscriptions.problems()

    def _availability_out(self, key: Key) -> Out:
        payload = AVAILABLE if self._availability.get(key) else UNAVAILABLE
        return Out(self.topics.drive_availability(*key), payload.encode(), retain=True)

    # -- the outbox ----------------------------------------------------------------------

    def _put(self, out: Out, *, wake: bool = True) -> None:
        self._outbox.put(out)
        if wake:
            self._wake.set()

    def _put_error(self, out: Out) -> None:
        self._outbox.put_error(out)
        self._wake.set()

    def _announce(self) -> None:
        """Everything retained, again: discovery (made as it is sent), availability, the
        latest states."""
        self._outbox.announce(
            Out(topic, compact_json(body), retain=True)
            for topic, body in iter_discovery(
                self.config, self.topics, self._gateway, self._limits.known
            )
        )
        # Only the drives polled already: "offline" for a drive not polled yet
        # would be a guess (it follows its first poll).
        for key in self._availability:
            self._put(self._availability_out(key), wake=False)
        for out in self._latest.values():
            self._put(out, wake=False)
        self._wake.set()

    async def _send(self, client: Client) -> None:
        await self._outbox.send(client, self.config.qos)

    async def _publisher(self, client: Client) -> None:
        while True:
            await self._wake.wait()  # the gateway's batch did the gathering: no timer here
            self._wake.clear()
            if self._closing:
                continue  # a clean stop: _say_offline sends what waits, on its own time
            self._idle.clear()
            try:
                await self._send(client)
            finally:
                self._idle.set()

    # -- the connection ------------------------------------------------------------------

    def _make_client(self) -> Client:
        return new_client(
            self.config,
            identifier=self.config.client_id,
            will=Will(self.topics.availability, UNAVAILABLE, self.config.qos, retain=True),
            max_in_flight=MAX_IN_FLIGHT,
            max_payload=MAX_PAYLOAD_BYTES,
        )

    async def _run(self) -> None:
        await keep_connected(
            self._make_client,
            self._connection,
            url=self.config.url,
            log=_log,
            ceiling_s=BACKOFF_MAX_S,
            stats=self.stats,
            who=f" as {self.topics.gateway}",
        )

    async def _connection(self, client: Client, connected: Callable[[], None]) -> None:
        """One connection: set up, then publish and receive until it fails."""
        self._epoch += 1  # the commands of this connection, from its first message
        self._session_name = f"mqtt session {self._epoch}"
        # The receiver runs from the start: the set-up waits for the broker's answers (a
        # SUBACK, the PUBACK of "online"), which come behind the messages sent to us
        # before them. Left unread, past the client's max_queued_messages, they stop it
        # reading, and those answers never came: a flood on the command topics at a
        # (re)connection hung the bridge for ever, silent.
        receiver = reader(self._receiver(client), "mqtt receiver")
        try:
            await self._setup(client)
            connected()
            await self._session(client, receiver)
        except asyncio.CancelledError:
            if self._closing:
                await self._say_offline(client)
            raise  # and the clean disconnect: the broker drops the will
        finally:
            receiver.cancel()  # (awaited by the session, when there was one)
            self._client = None
            if self._sweep is not None:  # it ran on this connection
                await cancel_and_wait({self._sweep})
            self._presence.lost()
            self._epoch += 1  # commands received on that connection are stale now
            session, self._session_name = self._session_name, None
            if session is not None and self._gateway is not None:
                self._gateway.disconnected(session)  # its connection-scoped leases lapse

    async def _say_offline(self, client: Client) -> None:
        """A clean stop: what is waiting, then "offline" (a clean disconnect has no will)."""
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(max(0.1, self._close_by - loop.time())):
                # Not an announcement's configs not made yet: they are retained from the
                # last start, and the next one announces them all again.
                self._outbox.announcing = None
                await self._send(client)
                await client.publish(
                    self.topics.availability, UNAVAILABLE, qos=self.config.qos, retain=True
                )
        except (MqttError, TimeoutError, asyncio.CancelledError) as exc:
            # The disconnect that follows is clean, so the broker drops the will:
            # "online" stays until the gateway connects again. Said loudly.
            _log.warning("MQTT: could not say offline before stopping: %s",
                         exc or type(exc).__name__)  # fmt: skip
            if isinstance(exc, asyncio.CancelledError):
                raise

    async def _setup(self, client: Client) -> None:
        """Subscribe, say online, and queue everything retained again."""
        qos = self.config.qos
        subscribe = self._subscriptions.subscribe
        await subscribe(client, self.topics.command_filter, qos=qos, unheard="commands")
        if self.config.discovery or self._presence.enabled:
            await subscribe(client, self._birth, qos=qos, unheard="Home Assistant's status")
        await client.publish(self.topics.availability, AVAILABLE, qos=qos, retain=True)
        self._client = client
        self._announce()
        if self._sweeper is None or not self._sweeper.done:
            self._start_sweep(client)

    def _start_sweep(self, client: Client) -> None:
        """Clear what this gateway left retained and no longer serves (:mod:`._sweep`)."""
        if self._gateway is None:
            return
        # Made one at a time: only the topics are kept (see _outbox).
        made = (t for t, _ in iter_discovery(self.config, self.topics, self._gateway))
        drives = [drive.key for drive in self._gateway.drives]
        self._sweeper, sweeping = sweep_and_say(
            self.config, self.topics, client, made, self.stats, drives
        )
        self._sweep = asyncio.create_task(sweeping, name="mqtt sweep")

    async def lines_changed(
        self, added: Sequence[ServedLine], removed: Sequence[ServedLine]
    ) -> None:
        """A reload added or removed lines, on the same session: the removed drives'
        retained state, availability and discovery cleared (a sweep), their commands
        waiting refused; discovery published again for every drive served now."""
        for line in removed:
            for node in line.drives:
                key = (line.config.name, node)
                self._latest.pop(key, None)
                self._availability.pop(key, None)
                worker = self._workers.pop(key, None)
                queue = self._commands.pop(key, None)
                if worker is not None and key not in self._busy:
                    worker.cancel()  # a write under way ends as the gateway answers it
                if queue is not None and queue.qsize():
                    self.stats.discarded += queue.qsize()
        client = self._client
        if client is None:  # swept and announced at the next connection
            self._sweeper = None
            return
        if self._sweep is not None:
            await cancel_and_wait({self._sweep})
        self._announce()
        self._start_sweep(client)
        self._wake.set()

    async def _session(self, client: Client, receiver: asyncio.Task[None]) -> None:
        """Publish, and receive (*receiver*), until the connection fails (raises its MqttError)."""
        tasks = {asyncio.create_task(self._publisher(client), name="mqtt publisher"), receiver}
        if self._gateway is not None and self._presence.enabled:
            keeper = self._presence.keep(self._gateway, self._session_name)
            tasks.add(asyncio.create_task(keeper, name="mqtt home assistant lease"))
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            await cancel_and_wait(tasks)
        for task in done:
            task.result()  # the connection's error
        raise MqttError("the session ended")  # both loops run until an error

    async def _receiver(self, client: Client) -> None:
        async for message in client.messages:
            if self._sweeper is not None and self._sweeper.feed(message):
                continue  # what the sweep reads (and its echo): never a command
            topic, payload = message.topic, message.payload
            if topic == self._birth:
                # Home Assistant (re)started: it needs the configs and states again. A
                # retained birth is the one it sent before we connected: already covered.
                if payload == AVAILABLE.encode() and not message.retain:
                    self._rediscovery.birth()
                self._presence.heard(payload)
                continue
            self._receive_command(topic, payload, retained=message.retain, length=message.length)

    # -- commands ------------------------------------------------------------------------

    def _drive(self, line: str, node: int) -> GatewayDrive | None:
        return None if self._gateway is None else self._gateway.drive(line, node)

    def _receive_command(
        self, topic: str, payload: bytes, *, retained: bool, length: int | None = None
    ) -> None:
        self.stats.commands += 1
        parsed = self.topics.parse_command(topic)
        drive = None if parsed is None else self._drive(*parsed[:2])
        if parsed is None or drive is None:
            self.stats.ignored += 1
            if _log.isEnabledFor(logging.DEBUG):  # the excerpt costs more than the rest
                _log.debug("MQTT: %s names no drive of this gateway: ignored", excerpt(topic))
            return
        line, node, what = parsed
        # Spent before the payload is read: past the budget, this is all a flood costs.
        stop = what == "command" and len(payload) < 64 and payload.strip() == b"stop"
        if not self._intake.admit((line, node), stop=stop, topic=lambda: excerpt(topic)):
            self.stats.throttled += 1
            return
        # The topic as replies and logs show it: the client's part of it excerpted.
        topic = topic[: len(topic) - len(what)] + excerpt(what)
        too_long = oversized(len(payload) if length is None else length)
        if too_long is not None:
            self.stats.oversized += 1
            self._refuse(drive, topic, what, payload, too_long, size=length)
            return
        if retained:
            # Stored by the broker, not sent now: carrying it out would replay it.
            self._refuse(drive, topic, what, payload, _RETAINED)
            return
        queue = self._commands.get((line, node))
        if queue is None:
            queue = self._commands[line, node] = asyncio.Queue(MAX_COMMANDS)
            self._workers[line, node] = asyncio.create_task(
                self._worker((line, node), drive, queue), name=f"mqtt commands {line} {node}"
            )
        if what == "command" and payload.strip() == b"stop":
            # A stop waits behind no command: what waits is dropped (refused, audited),
            # and the stop follows the write under way, if any, at once.
            while not queue.empty():
                _, old_topic, old_payload, old_what = queue.get_nowait()
                self._refuse(drive, old_topic, old_what, old_payload, DROPPED_BY_STOP)
        try:
            queue.put_nowait((self._epoch, topic, payload, what))
        except asyncio.QueueFull:
            self._refuse(
                drive,
                topic,
                what,
                payload,
                WriteResult(
                    Refusal.BUSY, f"{MAX_COMMANDS} commands are already waiting for this drive"
                ),
            )

    async def _worker(
        self, key: Key, drive: GatewayDrive, queue: asyncio.Queue[tuple[int, str, bytes, str]]
    ) -> None:
        """Carry out one drive's commands, in order."""
        while not self._closing:
            epoch, topic, payload, what = await queue.get()
            if epoch != self._epoch:
                self.stats.discarded += 1
                _log.debug("MQTT: %s %r discarded: received before the connection was lost",
                           topic, excerpt(payload))  # fmt: skip
                continue
            self._busy.add(key)
            try:
                await self._carry_out(drive, topic, what, payload)
            except Exception:  # a bug: the worker, and the drive's next stop, go on
                self.stats.failed += 1
                _log.exception("MQTT: %s %r: the command failed", topic, excerpt(payload))
                self._refuse(
                    drive,
                    topic,
                    what,
                    payload,
                    WriteResult(Refusal.NO_ANSWER, "the gateway failed to carry it out"),
                )
            finally:
                self._busy.discard(key)

    async def _carry_out(self, drive: GatewayDrive, topic: str, what: str, payload: bytes) -> None:
        request = parse_command(drive.profile, what, payload)
        if isinstance(request, WriteResult):
            self._refuse(drive, topic, what, payload, request)
            return
        assert self._gateway is not None
        await self._presence.before(self._gateway, drive, request, self._session_name)
        result = await self._gateway.write(
            CLIENT, drive, request, connection=self._session_name
        )  # audited there
        if result.refusal is not None:
            self._refuse(drive, topic, what, payload, result, audited=True)
        else:
            self._presence.after(drive, request)

    def _refuse(
        self,
        drive: GatewayDrive,
        topic: str,
        what: str,
        payload: bytes,
        result: WriteResult,
        *,
        audited: bool = False,
        size: int | None = None,
    ) -> None:
        """Refuse a command; *size*: its payload's, when *payload* is only the head of it."""
        self.stats.refused += 1
        text = excerpt(payload, size=size)
        error = error_text(result)
        _log.debug("MQTT: %s %r refused: %s", topic, text, error)
        if not audited and self._gateway is not None:
            # The gateway audits what it judges; this was refused before it got there.
            self._gateway.refused(CLIENT, drive, f"mqtt {excerpt(what)}", text, result)
        if not self._intake.reply((drive.line.name, drive.node)):
            # Counted and audited, not answered: a flood gets no flood of replies.
            self.stats.errors_dropped += 1
            return
        reason = None if result.refusal is None else result.refusal.value
        body = {"topic": topic, "payload": text, "error": error, "reason": reason,
                "time": time.time()}  # fmt: skip
        line, node = drive.line.name, drive.node
        self._put_error(Out(self.topics.error(line, node), json.dumps(body).encode(), False))
        event = refused_event(excerpt(what), text, error, reason)
        self._put_error(Out(self.topics.event(line, node), json.dumps(event).encode(), False))

    # -- stopping ------------------------------------------------------------------------

    async def close(self) -> None:
        """Stop: finish the write under way, flush, say "offline", disconnect."""
        if self._task is None:
            return
        self._closing = True
        self._rediscovery.cancel()
        self._epoch += 1  # commands waiting are not carried out any more
        loop = asyncio.get_running_loop()
        # A write under way finishes (a write and its read-back stay together; its
        # worker then sees _closing and ends); the idle workers end now.
        busy = [task for key, task in self._workers.items() if key in self._busy]
        for key, task in self._workers.items():
            if key not in self._busy:
                task.cancel()
        if busy:
            await asyncio.wait(busy, timeout=CLOSE_TIMEOUT_S)
        await cancel_and_wait(set(self._workers.values()))
        waiting = sum(queue.qsize() for queue in self._commands.values())
        if waiting:
            self.stats.discarded += waiting
            _log.debug("MQTT: %d commands discarded: the gateway is stopping", waiting)
        # The connection's own task says "offline" as it ends (see _connection), after
        # anything it was publishing: never before an "online" still on its way.
        self._close_by = loop.time() + CLOSE_TIMEOUT_S
        # The batch on its way finishes first (no new one starts: see _publisher); an
        # announcement's configs not made yet wait for the next start.
        self._outbox.announcing = None
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout_at(self._close_by):
                await self._idle.wait()
        # Its "offline" and its disconnect take up to CLOSE_TIMEOUT_S and the client's
        # own close time: cancelled again sooner, it would leave "online" retained.
        await cancel_and_wait({self._task}, patience_s=2 * CLOSE_TIMEOUT_S)
        self._task = None
        pending = self._outbox.abandon()
        if pending:
            self.stats.lost += pending
            _log.debug("MQTT: %d messages not published before stopping", pending)
