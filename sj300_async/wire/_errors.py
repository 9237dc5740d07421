"""The library's exception tree.

Everything the library raises on purpose derives from :class:`SJ300Error`.
Where an error resembles a builtin, it inherits that too, so code that
already handles ``ValueError``, ``TimeoutError`` or ``ConnectionError`` keeps
working (the python-can pattern)::

    SJ300Error
    ├── ProtocolError
    │   ├── LocalProtocolError (also ValueError)   you asked for something invalid
    │   │   └── ReadOnlyError                      a write on a read-only bus
    │   └── RemoteProtocolError                    the line sent something invalid
    ├── NakError                                   the drive answered NAK + code
    ├── ReplyTimeoutError (also TimeoutError)      no valid answer in time
    └── TransportError (also ConnectionError)      the link itself failed
        └── BusClosedError                         the bus was closed

``asyncio.CancelledError`` is never caught, wrapped or converted.
"""

from __future__ import annotations

__all__ = [
    "BusClosedError",
    "LocalProtocolError",
    "NakError",
    "ProtocolError",
    "ReadOnlyError",
    "RemoteProtocolError",
    "ReplyTimeoutError",
    "SJ300Error",
    "TransportError",
]


class SJ300Error(Exception):
    """Root of every error this library raises on purpose."""


class ProtocolError(SJ300Error):
    """Something broke the protocol's rules. Not raised itself: see the two subclasses."""


class LocalProtocolError(ProtocolError, ValueError):
    """The caller asked for something the protocol does not allow.

    Raised before a single byte is produced, so nothing reaches the wire.
    """


class ReadOnlyError(LocalProtocolError):
    """A command that changes a drive was refused because the bus is read-only."""


class RemoteProtocolError(ProtocolError):
    """The line delivered something the protocol does not allow (bad BCC, bad characters...)."""


class NakError(SJ300Error):
    """A drive answered with a negative reply (NAK).

    Attributes:
        node: the drive's node address (1..32).
        code: the drive's error code, a :class:`~sj300_async.NakCode` when known,
            else the plain integer the drive sent.
    """

    def __init__(self, node: int, code: int, message: str | None = None) -> None:
        self.node = node
        self.code = code
        name = getattr(code, "description", None) or f"code {int(code):02d}"
        super().__init__(message or f"node {node:02d} answered NAK {int(code):02d} ({name})")

    def __reduce__(self) -> tuple[type[NakError], tuple[int, int, str]]:
        return (type(self), (self.node, self.code, str(self)))


class ReplyTimeoutError(SJ300Error, TimeoutError):
    """No valid reply arrived before the response deadline."""


class TransportError(SJ300Error, ConnectionError):
    """The transport failed: could not connect, the link dropped, a write failed."""


class BusClosedError(TransportError):
    """The bus has been closed; it takes no more requests."""
