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
    """No valid reply arrived before the response deadline.

    The bus raises it once a call has used up its attempts (or its call
    deadline), with every figure in the message: ``node 04 did not answer
    command 04: 3 attempts of 500 ms each, 2.62 s in all``.

    Attributes:
        attempts: attempts made (each one a whole response time-out; 0 when the
            call deadline passed before the line was free).
        elapsed_s: seconds the whole call took, queueing and drains included,
            or None when not known.
        timeout_s: the response time-out of one attempt (the longest, if they
            differed), or None when not known.
    """

    def __init__(
        self,
        message: str = "",
        attempts: int = 1,
        elapsed_s: float | None = None,
        timeout_s: float | None = None,
    ) -> None:
        # One argument for OSError (TimeoutError's base), which would read
        # several as errno and strerror.
        super().__init__(message)
        self.attempts = attempts
        self.elapsed_s = elapsed_s
        self.timeout_s = timeout_s

    def __reduce__(
        self,
    ) -> tuple[type[ReplyTimeoutError], tuple[str, int, float | None, float | None]]:
        return (type(self), (str(self), self.attempts, self.elapsed_s, self.timeout_s))


class TransportError(SJ300Error, ConnectionError):
    """The transport failed: could not connect, the link dropped, a write failed."""


class BusClosedError(TransportError):
    """The bus has been closed; it takes no more requests."""
