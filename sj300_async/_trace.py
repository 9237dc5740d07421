"""The trace hook: every frame that crosses the line, with a timestamp."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

__all__ = ["TraceHook", "TraceRecord"]


@dataclass(frozen=True, slots=True)
class TraceRecord:
    """One frame seen on the line."""

    #: Event-loop time (``loop.time()``) when the bytes were written or received.
    timestamp: float
    #: ``"tx"`` for what the host wrote, ``"rx"`` for what the parser made of the input.
    direction: Literal["tx", "rx"]
    #: The frame written (tx), or the received frame / discarded bytes (rx).
    data: bytes
    #: What the parser yielded (rx only).
    event: Any = None


#: A callable that receives every :class:`TraceRecord`. It must not block.
TraceHook = Callable[[TraceRecord], None]
