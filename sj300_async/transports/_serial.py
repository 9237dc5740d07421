"""Serial transport through pyserial-asyncio-fast.

pyserial-asyncio-fast is the maintained fork of pyserial-asyncio: it opens
and closes the port off the event loop (0.6 blocks the loop on both), and it
is a real asyncio.Transport. pyserial is imported only when a serial bus is
opened, so the rest of the library works where it is not installed.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from ..wire._errors import TransportError
from ..wire._line import LineSettings

__all__ = ["serial_connector"]

_PARITY = {"N": "N", "E": "E", "O": "O"}


def serial_connector(
    device: str, line: LineSettings
) -> Callable[[Callable[[], asyncio.Protocol]], Any]:
    """Return a connector that opens *device* (a path or a pyserial URL) with *line*'s settings."""
    if line.baudrate == 0:
        raise TransportError("a serial line needs a baud rate")

    async def connect(protocol_factory: Callable[[], asyncio.Protocol]) -> asyncio.BaseTransport:
        import serial
        import serial_asyncio_fast

        loop = asyncio.get_running_loop()
        try:
            transport, _ = await serial_asyncio_fast.create_serial_connection(
                loop,
                protocol_factory,
                device,
                baudrate=line.baudrate,
                bytesize=line.bytesize,
                parity=_PARITY[line.parity],
                stopbits=line.stopbits,
            )
        except serial.SerialException as exc:
            raise TransportError(f"cannot open serial port {device}: {exc}") from exc
        # The transport hands itself to the protocol (connection_made) and starts
        # reading from callbacks it has queued with call_soon. One loop turn runs
        # them, in order, so the caller gets a transport that is fully connected:
        # a pause_reading() right away is not undone by the reader starting later.
        await asyncio.sleep(0)
        return transport

    return connect
