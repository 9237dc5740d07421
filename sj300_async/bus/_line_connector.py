"""The connector for a URL that names a real line: a TCP bridge, RFC 2217 or a serial port.

One place for the choice, shared by :func:`~._open.open_bus` and the
sniffer (:mod:`._listen`). ``sim://`` and ``replay://`` are no real line:
``open_bus`` builds their connectors itself.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

from ..transports import rfc2217_connector, serial_connector, tcp_connector
from ..wire import LineSettings, LocalProtocolError
from ._url import BusAddress

__all__ = ["AnyConnector", "line_connector"]

#: A connector for any protocol (the link's ``Connector`` is this, for its own).
AnyConnector = Callable[[Callable[[], asyncio.Protocol]], Awaitable[asyncio.BaseTransport]]


def line_connector(address: BusAddress, line: LineSettings) -> AnyConnector:
    """The connector for *address* with the line settings *line*.

    Raises:
        LocalProtocolError: a serial or RFC 2217 line without a baud rate, or
            a URL that names no real line.
    """
    if address.scheme == "tcp":
        return tcp_connector(address.host, address.port)
    if address.scheme == "rfc2217":
        if line.baudrate == 0:
            raise LocalProtocolError(f"an RFC 2217 port needs a baud rate: {address.description}")
        return rfc2217_connector(address.host, address.port, line)
    if address.scheme == "serial":
        if line.baudrate == 0:
            raise LocalProtocolError(f"a serial line needs a baud rate: {address.description}")
        return serial_connector(address.device, line)
    raise LocalProtocolError(f"{address.description} is not a real line")
