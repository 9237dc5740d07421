"""Modbus TCP: an asyncio.Protocol per connection over the sans-IO framer (:mod:`._framing`).

Reads are answered from the drive's :class:`~._registers.RegisterMap`
over its latest served view (``drive.served``: the gateway's cache and its
judgement of it, freshness included; no read reaches a line),
at once, in the callback that received them. Writes go through the
gateway's write path (``gateway.write``, which does reach the line,
through its arbiter), and a refusal is answered with
:data:`~._registers.REFUSAL_CODES`' exception.

Decisions:

- **Pipelining: strictly in order.** A connection's requests are answered
  in the order they came, each with its own transaction id and unit id.
  While a write is carried out, the requests behind it wait (reading pauses
  once more than :data:`PAUSE_BYTES` are buffered) and are answered when it
  is done. Answering a later read first would be allowed by the spec, but a
  SCADA that writes a set point and then reads it expects to read it back.
  Several reads in one segment get their answers in one ``write``.
- **A broken frame closes the connection** (see :mod:`._framing`): one
  WARNING line per :data:`~sj300_async.gateway.LOG_INTERVAL_S` for the
  whole listener, the rest at DEBUG, with a bounded hex excerpt, and
  counted (``sj300_modbus_bad_frames_total``). No input is logged with a
  traceback.
- **A unit id with no drive behind it gets 0x0A**, whatever its request
  (the unit is judged first, as a gateway routes before the target
  decodes): no data, and no other exception, for a unit that does not
  exist. Unit 0 is no broadcast here: no drive has it. Unit 255 is the
  listener's summary (:mod:`._summary`), read-only.
- **Limits**: ``max_connections`` (newcomers past it are accepted and
  closed at once, by the :class:`~sj300_async.gateway.Listener`, the HTTP
  northbound's too) and ``idle_timeout_s`` (a connection with no request
  for that long, and no write of its own in progress, is closed). At
  ``max_connections`` a newcomer from an address holding fewer takes the
  place of the heaviest address's connection whose last request is oldest
  (one with a write in progress excepted), closed at once.
- **A connection is a client**: its IP address is the audit log's "who",
  the lease holder and the metrics' label; ``"IP:port"`` names the
  connection, whose end lapses a connection-scoped lease
  (``gateway.disconnected``) at once: a run or frequency command of its
  still under way is cancelled by that lapse, and a heartbeat of its not
  yet carried out is refused (the connection it would renew is gone). A
  stop or parameter write still under way is carried out (and audited);
  its answer has nowhere to go.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Coroutine
from dataclasses import dataclass
from typing import Any, Final, cast

from .. import (
    ConnectionLimit,
    Endpoint,
    GatewayDrive,
    GatewayView,
    Heartbeat,
    Listener,
    ListenerLimits,
    RateLimitedLog,
    Refusal,
    Slot,
    WriteRequest,
    WriteResult,
)
from ._clients import ClientCounters
from ._framing import (
    NEED_DATA,
    Exc,
    FrameError,
    Framer,
    ReadRegisters,
    Refused,
    WriteRegisters,
    encode_exception,
    encode_registers,
    encode_written,
    excerpt,
)
from ._registers import REFUSAL_CODES, ReadCache, RegisterMap
from ._summary import SUMMARY_UNIT, Summary

__all__ = ["PAUSE_BYTES", "ModbusServer", "Unit"]

_log = logging.getLogger("sj300_async.gateway.modbus")

#: Bytes of requests buffered behind a write in progress before reading pauses.
PAUSE_BYTES: Final = 4096

_Answer = bytes | Coroutine[Any, Any, bytes]


@dataclass(frozen=True, slots=True)
class Unit:
    """What a unit id stands for: a drive, its line's map, and its answered reads."""

    drive: GatewayDrive
    registers: RegisterMap
    cache: ReadCache


class ModbusServer:
    """The listener and its connections (see the module docstring)."""

    def __init__(
        self,
        units: dict[int, Unit],
        gateway: GatewayView,
        limits: ListenerLimits,
        counters: ClientCounters,
        limit: ConnectionLimit | None = None,
    ) -> None:
        self.units = units
        #: Unit 255: every drive's record side by side (see :mod:`._summary`).
        self.summary = Summary({unit_id: unit.drive for unit_id, unit in units.items()})
        self.gateway = gateway
        self.idle_timeout_s = limits.idle_timeout_s
        self.counters = counters
        #: Shared by every listener of the northbound: max_connections is for them all.
        self.limit = limit or ConnectionLimit(
            "modbus", limits.max_connections, _log, limits.per_address
        )
        #: Frames that could not be framed (each closed its connection).
        self.bad_frames = 0
        self._bad_frame_log = RateLimitedLog(_log)
        self._connections: set[_Connection] = set()
        self._server: Listener | None = None

    def set_units(self, units: dict[int, Unit]) -> None:
        """The drives it serves from the next request on (a reload changed the lines)."""
        self.units = units
        self.summary = Summary({unit_id: unit.drive for unit_id, unit in units.items()})

    async def start(self, endpoint: Endpoint) -> None:
        """Listen on *endpoint* (port 0: any free port, then read :attr:`port`).

        Raises:
            OSError: the address cannot be bound.
        """
        server = Listener(lambda address: _Connection(self, address), self.limit)
        await server.start(endpoint.host, endpoint.port)
        self._server = server
        _log.info("Modbus TCP on %s:%d, units %s", endpoint.host, self.port, sorted(self.units))

    @property
    def port(self) -> int:
        """The port it listens on (the real one when asked for port 0)."""
        sockets = self._server.sockets if self._server is not None else ()
        return int(sockets[0].getsockname()[1]) if sockets else 0

    async def close(self) -> None:
        """Stop listening, close every connection; return once their writes are done."""
        if self._server is not None:
            self._server.close()
        writes = [c.pending for c in self._connections if c.pending is not None]
        for connection in list(self._connections):
            connection.close()
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None
        # A write already handed to the gateway gets its outcome (and its audit line).
        await asyncio.gather(*writes, return_exceptions=True)

    def bad_frame(self, connection: str, error: FrameError) -> None:
        self.bad_frames += 1
        self._bad_frame_log.log(
            "modbus %s: %s; connection closed. First bytes: %s",
            connection,
            error.reason,
            excerpt(error.data),
        )


class _Connection(asyncio.Protocol):
    """One client connection: frames in, answers out, in order (module docstring)."""

    def __init__(self, server: ModbusServer, address: str) -> None:
        self.server = server
        #: The client's address as the listener admitted it (its slot is released under it).
        self.address = address
        self.framer = Framer()
        self.transport: asyncio.Transport | None = None
        self.client = "?"
        self.name = "?"
        #: The write being carried out; the requests behind it wait.
        self.pending: asyncio.Task[bytes] | None = None
        self._loop = asyncio.get_running_loop()
        self._last_active = 0.0
        self._idle: asyncio.TimerHandle | None = None
        self._writing_paused = False
        self._reading_paused = False
        self._lost = False
        self._eof = False
        #: Its place in the limit, once made (ordered by its last request, for a newcomer).
        self._slot: Slot | None = None

    # -- asyncio's callbacks ---------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not isinstance(): uvloop's transports implement the interface without
        # deriving from asyncio's classes.
        transport = cast(asyncio.Transport, transport)
        self.transport = transport
        peer = transport.get_extra_info("peername") or ("?", 0)
        host, port = str(peer[0]), peer[1]
        self.client = host
        self.name = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
        self.server._connections.add(self)
        self._slot = self.server.limit.hold(self.address, self._evict)
        self._last_active = self._loop.time()
        self._idle = self._loop.call_later(self.server.idle_timeout_s, self._check_idle)

    def data_received(self, data: bytes) -> None:
        if self._lost:
            return
        self.framer.receive_data(data)
        self._last_active = self._loop.time()
        if self.pending is None and self._slot is not None:  # a write's turns it busy
            self._slot.active()
        if self.pending is None and not self._writing_paused:
            self._serve()
        self._update_reading()

    def eof_received(self) -> bool:
        # The client will send no more (``nc -N``, a script's shutdown): answer what it
        # sent, a write in progress included, then close.
        self._eof = True
        self._finish_at_eof()
        return True  # keep the transport open to answer

    def connection_lost(self, exc: Exception | None) -> None:
        if self._lost:
            return
        self._lost = True
        if self._slot is None:
            self.server.limit.release(self.address)
        else:  # released already if it was closed for a newcomer
            self._slot.release()
        self.server._connections.discard(self)
        if self._idle is not None:
            self._idle.cancel()
        self.server.gateway.disconnected(self.name)

    def pause_writing(self) -> None:
        # The client does not read its answers: stop answering, and reading, until it does.
        self._writing_paused = True
        self._update_reading()

    def resume_writing(self) -> None:
        self._writing_paused = False
        if self.pending is None:
            self._serve()
        if not self._finish_at_eof():
            self._update_reading()

    # -- serving ---------------------------------------------------------------------

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()

    def _evict(self) -> None:
        """Closed for a newcomer at max_connections (the limit counted and logged it).

        Aborted, not closed: the slot is already the newcomer's, and a close would
        wait for a client that does not read to take what is buffered."""
        if self.transport is not None:
            self.transport.abort()

    def _serve(self) -> None:
        """Answer every whole request buffered, up to a write (which the rest then waits for)."""
        answers: list[bytes] = []
        while not self._writing_paused:
            event = self.framer.next_event()
            if event is NEED_DATA:
                break
            if isinstance(event, FrameError):
                self._send(answers)  # what came before the bad frame was answered
                self.server.bad_frame(self.name, event)
                self.close()
                return
            answer = self._answer(event)
            if isinstance(answer, bytes):
                answers.append(answer)
                continue
            self.pending = self._loop.create_task(answer)
            self.pending.add_done_callback(self._written)
            if self._slot is not None:  # its write is carried out: not closed for a newcomer
                self._slot.busy()
            break
        self._send(answers)

    def _send(self, answers: list[bytes]) -> None:
        if answers and self.transport is not None:
            self.transport.write(answers[0] if len(answers) == 1 else b"".join(answers))

    def _answer(self, event: ReadRegisters | WriteRegisters | Refused) -> _Answer:
        """The answer to *event*, or the coroutine that carries its write out and answers."""
        server = self.server
        server.counters.request(self.client)
        unit = server.units.get(event.unit_id)
        if unit is None and event.unit_id != SUMMARY_UNIT:
            return self._exception(event, Exc.PATH_UNAVAILABLE)
        if type(event) is ReadRegisters:
            now = self._loop.time()
            if unit is None:  # the summary (unit 255)
                result = server.summary.read(event.address, event.count, now)
            else:
                result = unit.registers.read(
                    unit.drive.served, event.address, event.count, now, unit.cache
                )
            if type(result) is list:
                return encode_registers(event.transaction_id, event.unit_id, event.function, result)
            assert isinstance(result, Exc)
            return self._exception(event, result)
        if isinstance(event, Refused):
            _log.debug("modbus %s: refused with 0x%02x: %s", self.name, event.code, event.reason)
            return self._exception(event, event.code)
        if unit is None:  # the summary is read-only: commands go to a drive's unit
            return self._exception(event, Exc.ILLEGAL_FUNCTION)
        assert isinstance(event, WriteRegisters)
        words = list(event.values)
        request = unit.registers.decode_write(event.address, words)
        if isinstance(request, WriteResult):  # no write at all: audited here, refused
            what = f"register {event.address}"
            server.gateway.refused(self.client, unit.drive, what, words, request)
            assert request.refusal is not None
            return self._exception(event, REFUSAL_CODES[request.refusal])
        return self._write(unit, event, request)

    async def _write(self, unit: Unit, event: WriteRegisters, request: WriteRequest) -> bytes:
        gateway = self.server.gateway
        if self._lost and isinstance(request, Heartbeat):
            # Its connection closed before it ran: it must not renew (or take) a lease.
            result = WriteResult(
                Refusal.NO_LEASE, "its connection closed before it was carried out"
            )
            gateway.refused(self.client, unit.drive, "heartbeat", None, result)
            return self._exception(event, REFUSAL_CODES[Refusal.NO_LEASE])
        result = await gateway.write(self.client, unit.drive, request, connection=self.name)
        if result.refusal is not None:
            return self._exception(event, REFUSAL_CODES[result.refusal])
        # Function 6 echoes the value written; 16 answers how many registers.
        word = event.values[0] if event.function == 6 else len(event.values)
        return encode_written(
            event.transaction_id, event.unit_id, event.function, event.address, word
        )

    def _exception(self, event: ReadRegisters | WriteRegisters | Refused, code: Exc) -> bytes:
        self.server.counters.exception(self.client, code)
        return encode_exception(event.transaction_id, event.unit_id, event.function, code)

    def _written(self, task: asyncio.Task[bytes]) -> None:
        self.pending = None
        if self._lost:
            return
        if task.cancelled():
            self.close()
            return
        error = task.exception()
        if error is not None:
            # Not the client's input: the gateway's write path failed. One line; the
            # connection cannot be answered in order any more.
            _log.error("modbus %s: a write failed: %r; connection closed", self.name, error)
            self.close()
            return
        self._send([task.result()])
        self._last_active = self._loop.time()
        if self._slot is not None:
            self._slot.active()
        if not self._writing_paused:
            self._serve()
        if not self._finish_at_eof():
            self._update_reading()

    def _finish_at_eof(self) -> bool:
        """After the client's end of stream, close once every request is answered."""
        if self._eof and self.pending is None and not self._writing_paused:
            self.close()
            return True
        return False

    def _update_reading(self) -> None:
        """Read while answering; pause while the client does not read, or too much waits."""
        if self.transport is None or self._lost:
            return
        behind = self.pending is not None and self.framer.buffered > PAUSE_BYTES
        pause = self._writing_paused or behind
        if pause != self._reading_paused:
            self._reading_paused = pause
            if pause:
                self.transport.pause_reading()
            else:
                self.transport.resume_reading()

    def _check_idle(self) -> None:
        timeout = self.server.idle_timeout_s
        idle_s = self._loop.time() - self._last_active
        if self.pending is not None or idle_s < timeout:  # a write of its own is no idling
            wait = timeout if self.pending is not None else timeout - idle_s
            self._idle = self._loop.call_later(wait, self._check_idle)
            return
        self.server.limit.timed_out += 1
        _log.debug("modbus %s: idle for %g s: closed", self.name, timeout)
        self.close()
