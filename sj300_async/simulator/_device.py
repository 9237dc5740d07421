"""The serial-device server: a simulated bus on a terminal device that already exists.

Where :func:`open_pty_server` makes its own pseudo-terminal, this serves on
a path someone else made: one end of a ``socat`` pty pair (to put ser2net
or another bridge in front), or a real serial port, so the simulated drives
answer a host on a physical RS-485 line.

The device is opened in raw mode. With *settings*, its UART is set to that
speed and character format; without, the device keeps what it has (a
pseudo-terminal has no speed to speak of). A real port's own UART paces the
bytes, so *pacing* is for pseudo-terminals only; without *settings* or
*pacing*, no reply is faster than the quickest exchange on the fastest
line the drives run (see :class:`~._pacing.PlausibleLine`).

An RS-485 adapter that echoes what it sends would hand the simulator its
own replies: use one without local echo on the simulator's side.
"""

from __future__ import annotations

import asyncio
import os
import termios
import tty

from ..wire import LocalProtocolError
from ._fd_link import FdLink, FdServer
from ._model import BusModel
from ._pacing import LinePacing, PacedLine, server_line

__all__ = ["SerialDeviceServer", "serve_serial_device"]


def _configure(fd: int, settings: LinePacing) -> None:
    """Set the UART of *fd* to *settings*, modem lines ignored."""
    speed = getattr(termios, f"B{settings.baudrate}", None)
    if not isinstance(speed, int):
        raise LocalProtocolError(f"this system's serial driver has no {settings.baudrate} bps")
    iflag, oflag, cflag, lflag, _ispeed, _ospeed, cc = termios.tcgetattr(fd)
    cflag &= ~(termios.CSIZE | termios.PARENB | termios.PARODD | termios.CSTOPB)
    cflag |= termios.CLOCAL | termios.CREAD
    cflag |= termios.CS7 if settings.bytesize == 7 else termios.CS8
    if settings.parity != "N":
        cflag |= termios.PARENB
    if settings.parity == "O":
        cflag |= termios.PARODD
    if settings.stopbits == 2:
        cflag |= termios.CSTOPB
    termios.tcsetattr(fd, termios.TCSANOW, [iflag, oflag, cflag, lflag, speed, speed, cc])


class SerialDeviceServer(FdServer):
    """A simulated bus on an existing serial device. Use :func:`serve_serial_device`."""

    def __init__(
        self,
        bus: BusModel,
        path: str,
        settings: LinePacing | None,
        line: PacedLine | None,
        loop: asyncio.AbstractEventLoop,
    ) -> None:
        self.bus = bus
        #: The device served.
        self.path = path
        self._fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            tty.setraw(self._fd)
            if settings is not None:
                _configure(self._fd, settings)
            self._link = FdLink(self._fd, path, bus, line, loop)
        except BaseException:
            os.close(self._fd)
            raise
        self._closed = False

    def __repr__(self) -> str:
        return f"SerialDeviceServer(path={self.path!r}, closed={self._closed})"

    def _close_fds(self) -> None:
        os.close(self._fd)


async def serve_serial_device(
    bus: BusModel,
    path: str,
    pacing: LinePacing | None = None,
    *,
    settings: LinePacing | None = None,
    line: PacedLine | None = None,
) -> SerialDeviceServer:
    """Serve *bus* on the terminal device at *path* (see the module docstring).

    Args:
        pacing: pace the line at these settings (pseudo-terminals only);
            default: none with *settings* (the UART paces), else no reply sooner
            than the request and a short frame cross a 19200-baud line
            (:class:`~._pacing.PlausibleLine`);
            ``LineSettings(baudrate=0)``: answer at once.
        settings: set the device's UART to these (real serial ports).
        line: share this paced line; overrides *pacing*.

    Raises:
        OSError: the device cannot be opened or configured.
        LocalProtocolError: the system offers no such speed.
    """
    if line is None and pacing is None and settings is not None:
        paced = None  # a real UART: its own clock paces every byte
    else:
        paced = server_line(pacing, line)
    return SerialDeviceServer(bus, path, settings, paced, asyncio.get_running_loop())
