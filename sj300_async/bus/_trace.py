"""The trace hook: every chunk of bytes that crosses the line, with a timestamp."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

__all__ = ["TraceHook", "TraceRecord"]


@dataclass(frozen=True, slots=True)
class TraceRecord:
    """Bytes seen on the line, exactly as written or as they arrived."""

    #: Event-loop time (``loop.time()``) when the bytes were written or received.
    timestamp: float
    #: ``"tx"`` for what the host wrote, ``"rx"`` for what arrived.
    direction: Literal["tx", "rx"]
    #: The frame written (tx), or the chunk received (rx), byte for byte: a
    #: reply split across chunks shows in several records, and local echo
    #: shows as it arrived.
    data: bytes
    #: What the parser completed with this chunk (rx only): the protocol's
    #: replies, ``BadFrame`` and ``Discarded`` events, in order.
    events: tuple[object, ...] = ()
    #: Those of :attr:`events` the bus refused as the answer they look like
    #: because they came sooner than the line allows (rule 8 of
    #: docs/RELIABILITY.md): a peer faster than its URL's baud rate. The same
    #: objects, in order; empty on a healthy line.
    early: tuple[object, ...] = ()


#: A callable that receives every :class:`TraceRecord`. It must not block.
TraceHook = Callable[[TraceRecord], None]
