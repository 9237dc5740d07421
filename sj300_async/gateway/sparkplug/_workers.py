"""A device's DCMD metrics as writes: read, judged, queued per drive, carried out in order.

A command too long (:data:`MAX_COMMAND_BYTES`) or retained (stored by the
broker, not sent now) is not read at all; a DCMD carries at most
:data:`MAX_METRICS` metrics (the rest are refused, one audit line for all).

Writes go through the gateway like every other door's (client
``sparkplug``: one identity, as on MQTT; the lease, the grants, the
read-back, the audit log). A drive's commands run in order, each drive on
its own worker, at most :data:`MAX_COMMANDS` waiting (more are refused:
busy). A stop waits behind no command: what waits is dropped (refused,
audited), and the stop follows the write under way, if any, at once.

What is refused is audited, counted, and told on the device's
``Control/Last Refusal`` and ``Control/Refusals`` metrics in the next
DDATA (Sparkplug has no error reply; a host sees the write did not take,
and why). A command received in a Sparkplug session that is over is never
carried out, but a stop is always tried.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Mapping
from typing import Final, Protocol

from ...wire import Direction
from .. import (
    DROPPED_BY_STOP,
    GatewayView,
    Refusal,
    RunCommand,
    WriteRequest,
    WriteResult,
    excerpt,
)
from ._commands import judge
from ._device import Device
from ._payload import MalformedPayload, ReceivedMetric, decode_payload
from ._stats import SparkplugStats

__all__ = [
    "CLIENT",
    "MAX_COMMANDS",
    "MAX_COMMAND_BYTES",
    "MAX_METRICS",
    "CommandSession",
    "DeviceCommands",
]

_log = logging.getLogger("sj300_async.gateway.sparkplug")

#: The client every Sparkplug command comes from.
CLIENT: Final = "sparkplug"
#: Commands waiting for one drive, at most (more are refused: busy).
MAX_COMMANDS: Final = 16
#: The longest command read; a longer one is refused unread.
MAX_COMMAND_BYTES: Final = 65536
#: Metrics one DCMD may carry; the rest are refused (each would be a write and an audit line).
MAX_METRICS: Final = 64
_STOP: Final = RunCommand(Direction.STOP)

Key = tuple[str, int]
#: A judged DCMD metric waiting: its session, device, name as shown, value, write.
_Command = tuple[int, Device, str, object, WriteRequest]


class CommandSession(Protocol):
    """What the workers need of the edge node (:class:`~._node.EdgeNode`)."""

    @property
    def gateway(self) -> GatewayView | None: ...

    #: Counts Sparkplug sessions: a command of an older one is never carried out.
    @property
    def epoch(self) -> int: ...

    #: The connection a write names (a connection-scoped lease lapses with it).
    @property
    def session_name(self) -> str | None: ...

    @property
    def born(self) -> bool: ...

    def alive(self, key: Key) -> bool:
        """The host was told the drive *key* is alive (its DBIRTH stands)."""

    def refusal_changed(self, device: Device) -> None:
        """*device*'s latest refusal changed: its next DDATA tells it."""

    def bad(self, reason: str, text: str) -> None:
        """Input that changed nothing, counted by *reason* (``BAD_INPUTS``)."""


class DeviceCommands:
    """Each drive's command queue and worker, and its refusals (see the module docstring)."""

    def __init__(
        self, session: CommandSession, stats: SparkplugStats, devices: Mapping[str, Device]
    ) -> None:
        """*devices*: the edge node's devices by device id (filled when it starts)."""
        self._session = session
        self._devices = devices
        self.stats = stats
        #: Per drive: the latest refusal in words, and how many so far.
        self.refusals: dict[Key, tuple[str, int]] = {}
        self._queues: dict[Key, asyncio.Queue[_Command]] = {}
        self._workers: dict[Key, asyncio.Task[None]] = {}
        self._closing = False

    def unread(self, what: str, length: int, *, retained: bool) -> WriteResult | None:
        """Why a command (NCMD or DCMD) is not read at all (too long, or retained), or None."""
        if length > MAX_COMMAND_BYTES:
            self._session.bad("oversized", f"{what}: {length} bytes, not read")
            return WriteResult(
                Refusal.MALFORMED, f"a command is at most {MAX_COMMAND_BYTES} bytes: not read"
            )
        if retained:
            # Stored by the broker, not sent now: carrying it out would replay it.
            self._session.bad("retained", f"{what}: a retained command is never carried out")
            return WriteResult(
                Refusal.NOT_ALLOWED,
                "a retained command is never carried out (publish commands without retain)",
            )
        return None

    def receive(self, topic: str, payload: bytes, length: int, *, retained: bool) -> None:
        """A DCMD on *topic* (*payload*: what was read of its *length* bytes)."""
        device = self._devices.get(topic.rsplit("/", 1)[-1])
        if device is None:
            self._session.bad("unknown_device", excerpt(topic))
            return
        unread = self.unread(f"DCMD to {device.id}", length, retained=retained)
        if unread is not None:
            self.refuse(device, "DCMD", excerpt(payload, size=length), unread)
            return
        try:
            decoded = decode_payload(payload)
        except MalformedPayload as exc:
            self._session.bad("malformed", f"DCMD to {device.id} {excerpt(payload)!r}: {exc}")
            self.refuse(
                device,
                "DCMD",
                excerpt(payload),
                WriteResult(Refusal.MALFORMED, "not a Sparkplug B payload"),
            )
            return
        for index, metric in enumerate(decoded.metrics):
            if index >= MAX_METRICS:
                extra = len(decoded.metrics) - MAX_METRICS
                self.stats.bad_input["too_many"] += extra
                self.stats.refused += extra - 1  # and one in _refuse: one audit line for all
                too_many = f"at most {MAX_METRICS} metrics per DCMD: {extra} refused"
                refused = WriteResult(Refusal.BUSY, too_many)
                self.refuse(device, "DCMD", f"{extra} more", refused)
                break
            self.take(device, metric)

    def take(self, device: Device, received: ReceivedMetric) -> None:
        """Judge one metric of a DCMD now; queue the write it asks for, or refuse it."""
        target, request, bad = judge(device, received)
        name = received.label if target is None else target.definition.name
        if bad is not None:
            self._session.bad(bad, f"DCMD {excerpt(name)} to {device.id}")
        if isinstance(request, WriteResult):
            self.refuse(device, name, received.value, request)
            return
        key = device.drive.key
        queue = self._queues.get(key)
        if queue is None:
            queue = self._queues[key] = asyncio.Queue(MAX_COMMANDS)
            self._workers[key] = asyncio.create_task(
                self._worker(queue), name=f"sparkplug commands {key[0]} {key[1]}"
            )
        if request == _STOP:
            while not queue.empty():
                _, _, old_name, old_value, _ = queue.get_nowait()
                self.refuse(device, old_name, old_value, DROPPED_BY_STOP)
        try:
            queue.put_nowait((self._session.epoch, device, name, received.value, request))
        except asyncio.QueueFull:
            self.refuse(
                device,
                name,
                received.value,
                WriteResult(Refusal.BUSY, f"{MAX_COMMANDS} commands already wait for this drive"),
            )

    async def _worker(self, queue: asyncio.Queue[_Command]) -> None:
        while not self._closing:
            epoch, device, name, value, request = await queue.get()
            if epoch != self._session.epoch and request != _STOP:  # a stop is always tried
                self.refuse(device, name, value, WriteResult(
                    Refusal.NO_ANSWER, "received in a Sparkplug session that is over"))  # fmt: skip
                continue
            try:
                await self._carry_out(device, name, value, request)
            except Exception:  # a bug: the worker, and the drive's next stop, go on
                _log.exception("Sparkplug: DCMD %s to %s failed", name, device.id)
                self.refuse(device, name, value, WriteResult(
                    Refusal.NO_ANSWER, "the gateway failed to carry it out"))  # fmt: skip

    async def _carry_out(
        self, device: Device, name: str, value: object, request: WriteRequest
    ) -> None:
        session = self._session
        why = self._not_now(request)
        if why is not None:
            session.bad("not_born", f"DCMD {name} to {device.id}")
            self.refuse(device, name, value, WriteResult(Refusal.NO_ANSWER, why))
            return
        assert session.gateway is not None
        result = await session.gateway.write(
            CLIENT, device.drive, request, connection=session.session_name
        )  # audited there
        if result.refusal is None:
            self.stats.writes += 1
            return
        # A stop is tried, dead or alive; the rest to a dead device counts as offline.
        dead = result.refusal == Refusal.NO_ANSWER and not session.alive(device.drive.key)
        if dead and request != _STOP:
            session.bad("offline", f"DCMD {name} to {device.id}")
        self.refuse(device, name, value, result, audited=True)

    def _not_now(self, request: WriteRequest) -> str | None:
        """Why *request* is not carried out now, or None: a stop is always tried.

        Nothing else is while no Sparkplug session stands (not born: the primary
        host is offline, or the births are not out yet): nobody the edge node
        answers to can have sent it. A drive the poller holds offline is the
        gateway's to refuse (no answer, counted ``offline`` here), after the
        value, as from every door (issue 42).
        """
        if request == _STOP or self._session.born:
            return None
        return "the edge node is not born (no Sparkplug session): nothing was sent"

    def refuse(
        self,
        device: Device,
        what: str,
        value: object,
        result: WriteResult,
        *,
        audited: bool = False,
    ) -> None:
        """Count, log, audit (unless the gateway did) and tell a refusal."""
        self.stats.refused += 1
        shown = None if value is None else excerpt(repr(value))
        text = str(result)
        _log.debug("Sparkplug: DCMD %s %s to %s refused: %s", excerpt(what), shown, device.id, text)
        gateway = self._session.gateway
        if not audited and gateway is not None:
            gateway.refused(CLIENT, device.drive, f"sparkplug {excerpt(what)}", shown, result)
        key = device.drive.key
        count = self.refusals.get(key, ("", 0))[1] + 1
        self.refusals[key] = (f"{excerpt(what)}: {text}", count)
        self._session.refusal_changed(device)

    async def close(self) -> None:
        """Stop every worker (the commands waiting are not carried out)."""
        self._closing = True
        for task in self._workers.values():
            task.cancel()
        await asyncio.gather(*self._workers.values(), return_exceptions=True)
