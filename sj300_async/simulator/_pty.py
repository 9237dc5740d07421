"""The pseudo-terminal server: a simulated bus any serial program can open by path.

The simulator owns the master side of a pty; :attr:`PtyServer.path` is the
slave (``/dev/pts/N``) that a terminal program, pyserial or the library's
serial transport opens like a serial port.

Two details make it behave like a wire:

- The slave is put in raw mode, so the line discipline translates nothing:
  a CR stays a CR (by default a tty turns it into LF) and nothing is echoed
  back into the simulator.
- The simulator keeps its own slave descriptor open. When the last client
  closes the slave, a master whose slave has no opener reads EIO forever,
  which would spin the event loop; with the slave held open the master
  simply sees no data until the next client comes.
"""

from __future__ import annotations

import asyncio
import os
import tty

from ._fd_link import FdLink, FdServer
from ._model import BusModel
from ._pacing import LinePacing, PacedLine, server_line

__all__ = ["PtyServer", "open_pty_server"]


class PtyServer(FdServer):
    """A simulated bus on a pseudo-terminal (see the module docstring).

    Use :func:`open_pty_server` to make one. Also an async context manager.
    """

    def __init__(
        self,
        bus: BusModel,
        line: PacedLine | None,
        loop: asyncio.AbstractEventLoop,
    ) -> None:
        self.bus = bus
        self._master, self._slave = os.openpty()
        try:
            #: The slave's path, for the serial program to open.
            self.path: str = os.ttyname(self._slave)
            tty.setraw(self._slave)
            self._link = FdLink(self._master, f"pty {self.path}", bus, line, loop)
        except BaseException:
            os.close(self._master)
            os.close(self._slave)
            raise
        self._closed = False

    def __repr__(self) -> str:
        return f"PtyServer(path={self.path!r}, closed={self._closed})"

    def _close_fds(self) -> None:
        os.close(self._master)
        os.close(self._slave)


async def open_pty_server(
    bus: BusModel,
    pacing: LinePacing | None = None,
    *,
    line: PacedLine | None = None,
) -> PtyServer:
    """Open a pseudo-terminal and serve *bus* on it; the slave's path is ``.path``.

    Args:
        pacing: pace the line at these settings; default: no reply sooner than
            the request and a short frame cross a 19200-baud line
            (:class:`~._pacing.PlausibleLine`);
            ``LineSettings(baudrate=0)``: answer at once.
        line: share this paced line (e.g. with a TCP server); overrides *pacing*.

    Raises:
        OSError: no pseudo-terminal could be opened.
    """
    return PtyServer(bus, server_line(pacing, line), asyncio.get_running_loop())
