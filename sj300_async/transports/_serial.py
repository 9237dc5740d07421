"""Serial transport through pyserial-asyncio-fast.

pyserial-asyncio-fast is the maintained fork of pyserial-asyncio: it opens
and closes the port off the event loop (0.6 blocks the loop on both), and it
is a real asyncio.Transport. pyserial is imported only when a serial bus is
opened, so the rest of the library works where it is not installed.

A port that opens but refuses the line settings (a pseudo-terminal or a USB
adapter without parity support answers ``tcsetattr`` with EINVAL, which
pyserial lets through as ``termios.error``, not an ``OSError``) raises
:class:`SerialSettingsError`, naming the device and the settings; the port
is closed again, so a reconnecting bus leaks no descriptor per attempt.
"""

from __future__ import annotations

import asyncio
import functools
import re
from collections.abc import Callable
from typing import Any

from ..wire import LineSettings, TransportError

__all__ = ["SerialSettingsError", "serial_connector"]

_PARITY = {"N": "N", "E": "E", "O": "O"}
#: A host (name, IPv4, or IPv6 in brackets) and a port: a TCP bridge without its
#: scheme. A device path has a slash (``/dev/ttyUSB0``) or no colon (``COM3``).
_HOST_PORT = re.compile(r"(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9][A-Za-z0-9.-]*):[0-9]{1,5}")


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
        settings: dict[str, Any] = {
            "baudrate": line.baudrate,
            "bytesize": line.bytesize,
            "parity": _PARITY[line.parity],
            "stopbits": line.stopbits,
        }
        refused: tuple[type[Exception], ...] = (ValueError, *_tty_errors())
        if device.startswith("socket://"):  # pyserial's raw TCP: no port to configure
            try:
                transport, _ = await serial_asyncio_fast.create_serial_connection(
                    loop, protocol_factory, device, **settings
                )
            except serial.SerialException as exc:
                raise TransportError(_open_failure(device, exc)) from exc
        else:
            opening = functools.partial(serial.serial_for_url, device, **settings)
            try:
                port = await loop.run_in_executor(None, opening)
            except serial.SerialException as exc:
                raise TransportError(_open_failure(device, exc)) from exc
            except refused as exc:
                raise SerialSettingsError(_refusal(device, line, exc)) from exc
            try:
                # Makes the port non-blocking, which sets the settings once more.
                transport, _ = await serial_asyncio_fast.connection_for_serial(
                    loop, protocol_factory, port
                )
            except BaseException as exc:
                port.close()
                if isinstance(exc, (refused, serial.SerialException)):
                    raise SerialSettingsError(_refusal(device, line, exc)) from exc
                raise
        # The transport hands itself to the protocol (connection_made) and starts
        # reading from callbacks it has queued with call_soon. One loop turn runs
        # them, in order, so the caller gets a transport that is fully connected:
        # a pause_reading() right away is not undone by the reader starting later.
        await asyncio.sleep(0)
        return transport

    return connect


class SerialSettingsError(TransportError):
    """The serial port opened but refused the line settings (the port is closed again)."""


def _tty_errors() -> tuple[type[Exception], ...]:
    """``termios.error`` where there is one (POSIX): not an OSError subclass."""
    try:
        import termios
    except ImportError:  # Windows: pyserial raises SerialException or ValueError there
        return ()
    return (termios.error,)


def _open_failure(device: str, exc: BaseException) -> str:
    """``cannot open serial port /dev/ttyUSB9: No such file or directory (errno 2)``.

    pyserial's message repeats the errno and the port
    (``[Errno 2] could not open port X: [Errno 2] No such file...: 'X'``):
    the operating system's error, which it was raised from, says it once.
    A device that looks like ``HOST:PORT`` gets the URL it probably meant.
    """
    cause = exc.__cause__ or exc.__context__
    if isinstance(cause, OSError) and cause.strerror:
        why = f"{cause.strerror} (errno {cause.errno})" if cause.errno else cause.strerror
    else:
        why = " ".join(str(exc).split()) or type(exc).__name__
    message = f"cannot open serial port {device}: {why}"
    if _HOST_PORT.fullmatch(device):
        message += (
            f"; a URL without a scheme names a serial port: for a TCP bridge use tcp://{device}"
        )
    return message


def _refusal(device: str, line: LineSettings, exc: BaseException) -> str:
    """``serial port /dev/pts/3 refuses 19200 8E1: Invalid argument (errno 22)``."""
    setting = f"{line.baudrate} {line.bytesize}{line.parity}{line.stopbits}"
    args = exc.args
    if len(args) == 2 and isinstance(args[0], int) and isinstance(args[1], str):
        why = f"{args[1]} (errno {args[0]})"  # termios.error's (errno, text)
    else:
        why = " ".join(str(exc).split()) or type(exc).__name__
    return f"serial port {device} refuses {setting}: {why}"
