"""TCP bridge transport: raw TCP to a serial device server (ser2net, Moxa NPort...).

The device server passes bytes between the socket and its RS-485 port
unchanged; the line settings live in the device server's configuration, and
the bus is told them only to compute wire times. Reconnection is the link's
job (:mod:`sj300_async._link`).
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable
from typing import Any

__all__ = ["tcp_connector"]


def tcp_connector(host: str, port: int) -> Callable[[Callable[[], asyncio.Protocol]], Any]:
    """Return a connector that opens a TCP connection to *host*:*port*."""

    async def connect(protocol_factory: Callable[[], asyncio.Protocol]) -> asyncio.BaseTransport:
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_connection(protocol_factory, host, port)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            # Frames are tiny and latency is everything: never wait to coalesce them.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        return transport

    return connect
