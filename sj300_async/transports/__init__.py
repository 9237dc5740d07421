"""Transports under the protocol adapter: in-memory loopback, serial, TCP bridge, RFC 2217, replay.

Each module provides a *connector*: an async callable that opens the
transport for a protocol factory (see :data:`sj300_async._link.Connector`).
They share one contract, tested by one suite run against each.
:class:`BufferedReads` is the socket-read base of every protocol adapter
of the library (the bus's, the simulator's servers').
"""

from __future__ import annotations

from ._buffered import BufferedReads
from ._faults import LineFaults
from ._loopback import LoopbackTransport, loopback_connector
from ._replay import ReplayMismatchError, ReplayScript, replay_connector
from ._rfc2217 import (
    Rfc2217Error,
    Rfc2217RefusedError,
    Rfc2217TimeoutError,
    Rfc2217Transport,
    rfc2217_connector,
)
from ._serial import SerialSettingsError, serial_connector
from ._tcp import tcp_connector

__all__ = [
    "BufferedReads",
    "LineFaults",
    "LoopbackTransport",
    "ReplayMismatchError",
    "ReplayScript",
    "Rfc2217Error",
    "Rfc2217RefusedError",
    "Rfc2217TimeoutError",
    "Rfc2217Transport",
    "SerialSettingsError",
    "loopback_connector",
    "replay_connector",
    "rfc2217_connector",
    "serial_connector",
    "tcp_connector",
]
