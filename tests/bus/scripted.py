"""A scripted drive behind the real loopback transport, for the arbiter tests.

The scripted peer parses requests with the library's RequestParser and
answers with frames the test chooses, at the times the test chooses, so each
arbiter rule can be exercised byte for byte. Expected reply bytes are built
here from the protocol reference (XOR BCC written out), not by the library.
"""

from __future__ import annotations

import asyncio
import functools
import operator
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass, field
from typing import Protocol

import sj300_async as sj
from sj300_async import bus as sjbus
from sj300_async import sj300 as sj3
from sj300_async.bus._bus import Bus
from sj300_async.transports import LineFaults


def xor_bcc(body: bytes) -> bytes:
    return b"%02X" % functools.reduce(operator.xor, body, 0)


def reply(body: bytes) -> bytes:
    """STX body BCC CR, with the BCC computed as the reference defines it."""
    return b"\x02" + body + xor_bcc(body) + b"\r"


def ack(node: int) -> bytes:
    return reply(b"%02d\x06" % node)


def ack_value(node: int, value: int) -> bytes:
    return reply(b"%02d\x06%08d" % (node, value))


def nak(node: int, code: int) -> bytes:
    return reply(b"%02d\x15%02d" % (node, code))


def status(node: int, a: int = 3, b: int = 1, c: int = 3) -> bytes:
    return reply(b"%02d%02d%02d%02d00" % (node, a, b, c))


#: What the peer sends back for one request: (delay in seconds, bytes) pairs.
Frames = list[tuple[float, bytes]]
Responder = Callable[[sj3.Request], Frames]


@dataclass
class ScriptedPeer:
    """A fake line: records every request and answers as ``respond`` says."""

    respond: Responder
    send: Callable[[bytes], None]
    requests: list[sj3.Request] = field(default_factory=list)
    #: Every byte that reached the peer, as it arrived.
    received: bytearray = field(default_factory=bytearray)
    bad: list[object] = field(default_factory=list)
    handles: list[asyncio.TimerHandle] = field(default_factory=list)
    closed: bool = False
    #: Every frame sent, with how late its timer fired (seconds past when the
    #: script said): a host pause shows here (see test_duplicates_and_late_replies).
    sent: list[tuple[bytes, float]] = field(default_factory=list)
    #: Seconds a character takes on the line (0: instant). A frame never goes
    #: out sooner than the request and itself take to cross the line, as with a
    #: real drive: the bus refuses an answer faster than that (BusTiming.answer_floor).
    char_s: float = 0.0

    def __post_init__(self) -> None:
        self._parser = sj3.RequestParser()

    def data_received(self, data: bytes) -> None:
        self.received += data
        loop = asyncio.get_running_loop()
        for event in self._parser.feed(data):
            if not isinstance(event, sj3.Request):
                self.bad.append(event)
                continue
            self.requests.append(event)
            if event.is_broadcast:
                continue
            for delay, frame in self.respond(event):
                wire = (len(event.frame) + len(frame)) * self.char_s
                due = loop.time() + max(delay, wire)
                self.handles.append(loop.call_at(due, self._send, frame, due))

    def _send(self, frame: bytes, due: float) -> None:
        if not self.closed:
            self.sent.append((frame, asyncio.get_running_loop().time() - due))
            self.send(frame)

    def close(self) -> None:
        self.closed = True
        for handle in self.handles:
            handle.cancel()


def answer_all(request: sj3.Request) -> Frames:
    """A healthy drive: answers every command immediately with a plausible reply."""
    node = request.node
    cmd = request.command
    if cmd is sj3.Command.READ_STATUS:
        return [(0.0, status(node))]
    if cmd is sj3.Command.READ_PARAMETER:
        return [(0.0, ack_value(node, 1000 + node))]
    if cmd is sj3.Command.CAN_STORE:
        return [(0.0, reply(b"%02d\x0601" % node))]
    if cmd in (sj3.Command.READ_MONITOR, sj3.Command.READ_TRIP_HISTORY):
        length = 104 if cmd is sj3.Command.READ_MONITOR else 440
        return [(0.0, reply(b"%02d" % node + b"0" * length))]
    return [(0.0, ack(node))]


@dataclass
class Rig:
    bus: Bus[sj.Drive, sj.Broadcast]
    peers: list[ScriptedPeer]
    trace: list[sjbus.TraceRecord]

    @property
    def peer(self) -> ScriptedPeer:
        return self.peers[-1]

    def written(self) -> list[bytes]:
        return [r.data for r in self.trace if r.direction == "tx"]


class MakeRig(Protocol):
    """The ``scripted`` fixture: ``async with scripted(respond, retries=...) as rig:``."""

    def __call__(
        self,
        respond: Responder = ...,
        *,
        to_host: LineFaults | None = None,
        to_peer: LineFaults | None = None,
        strip_echo: bool = False,
        **bus_kwargs: object,
    ) -> AbstractAsyncContextManager[Rig]: ...
