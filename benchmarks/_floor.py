"""The floors: what one round trip costs asyncio itself, with no protocol stack at all.

- Over TCP (:class:`EchoClient`): a bare ``asyncio.Protocol`` client that
  writes 8 bytes (the size of our requests) and waits on a future until a
  fixed-size answer has arrived from ``python -m benchmarks._servers echo``;
  no framing, no checks, no decoding. The tcp benchmark's floor, and the
  reference the scale benchmark's CPU per poll is divided by.
- :class:`BufferedEchoClient`: the same client on asyncio's other read path,
  ``BufferedProtocol``, reading into one reused buffer as our adapter does
  (:mod:`sj300_async.transports._buffered`) and copying each chunk out as
  ``bytes``. The plain floor's reads allocate 256 KiB each
  (``sock.recv(256 KiB)``), which costs an ``mmap``/``mremap``/``munmap``
  per read whenever glibc serves that size by ``mmap``; this floor shows
  what our stack costs over the same read path.
- In memory (:func:`memory_round_trips`): a future per transaction, resolved
  from a callback the loop runs on its next turn, as the loopback transport
  hands a reply over: the least an asyncio transaction with no socket costs.
"""

from __future__ import annotations

import asyncio
import socket
from typing import cast

from sj300_async.transports import BufferedReads

from ._servers import ECHO_REPLIES

__all__ = [
    "BufferedEchoClient",
    "EchoClient",
    "connect_echo",
    "echo_round_trips",
    "memory_round_trips",
]


class EchoClient(asyncio.Protocol):
    """The floor's client: writes a request, waits for the whole fixed-size reply."""

    def __init__(self) -> None:
        self._transport: asyncio.Transport | None = None
        self._waiter: asyncio.Future[None] | None = None
        self._missing = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # A cast, not isinstance(): uvloop's transports do not derive from asyncio's.
        self._transport = cast(asyncio.Transport, transport)
        sock = transport.get_extra_info("socket")
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # as our transport does

    def data_received(self, data: bytes) -> None:
        self._missing -= len(data)
        if self._missing <= 0 and self._waiter is not None:
            self._waiter.set_result(None)

    async def ask(self, kind: bytes) -> None:
        """One round trip: *kind* (``b"S"`` or ``b"M"``) names the reply's size."""
        assert self._transport is not None
        self._waiter = asyncio.get_running_loop().create_future()
        self._missing = len(ECHO_REPLIES[kind])
        self._transport.write(kind + b"0104\r\n\x00")  # 8 bytes, as our requests
        await self._waiter


class BufferedEchoClient(BufferedReads, EchoClient):
    """The floor's client reading into one reused buffer (asyncio's ``BufferedProtocol``),
    with the adapter's own read code."""

    def __init__(self) -> None:
        EchoClient.__init__(self)
        BufferedReads.__init__(self)


async def connect_echo(port: int, *, buffered: bool = False) -> EchoClient:
    """Connect an :class:`EchoClient` (or, *buffered*, a :class:`BufferedEchoClient`)
    to the echo server on 127.0.0.1:*port*."""
    loop = asyncio.get_running_loop()
    factory = BufferedEchoClient if buffered else EchoClient
    _transport, client = await loop.create_connection(factory, "127.0.0.1", port)
    return client


async def echo_round_trips(client: EchoClient, kind: bytes, n: int) -> int:
    """*n* sequential round trips of *kind*; returns *n*."""
    for _ in range(n):
        await client.ask(kind)
    return n


def _answer(future: asyncio.Future[None]) -> None:
    future.set_result(None)


async def memory_round_trips(n: int) -> int:
    """*n* in-memory transactions: a future each, answered on the loop's next turn."""
    loop = asyncio.get_running_loop()
    for _ in range(n):
        future = loop.create_future()
        loop.call_soon(_answer, future)
        await future
    return n
