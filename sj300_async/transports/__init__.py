"""Transports under the protocol adapter: in-memory loopback, serial, TCP bridge, RFC 2217, replay.

Each module provides a *connector*: an async callable that opens the
transport for a protocol factory (see :data:`sj300_async._link.Connector`).
They share one contract, tested by one suite run against each.
"""

from __future__ import annotations

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
from ._serial import serial_connector
from ._tcp import tcp_connector

__all__ = [
    "LineFaults",
    "LoopbackTransport",
    "ReplayMismatchError",
    "ReplayScript",
    "Rfc2217Error",
    "Rfc2217RefusedError",
    "Rfc2217TimeoutError",
    "Rfc2217Transport",
    "loopback_connector",
    "replay_connector",
    "rfc2217_connector",
    "serial_connector",
    "tcp_connector",
]
