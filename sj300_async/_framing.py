"""The STX..CR frame splitter shared by the reply parser and the request parser.

State machine (the whole of it lives in :meth:`FrameSplitter.feed`)::

    HUNTING --STX--> IN_FRAME --CR--> (frame complete) --> HUNTING
       ^  \\--other bytes: Discarded(GARBAGE)
       |     IN_FRAME --STX--> Discarded(RESTARTED), stay IN_FRAME (new frame)
       \\---- IN_FRAME --more than max_body bytes--> Discarded(OVERLONG) --> HUNTING

Rather than stepping byte by byte, each state searches the chunk with
``bytes.find`` for the next byte that can change it (STX when hunting; CR or
STX inside a frame). A chunk that is exactly one whole frame (the usual
case) is recognised by two searches and decoded without entering the loop.
The buffer of an incomplete frame never exceeds ``max_body`` bytes: memory
is bounded whatever the line sends.
"""

from __future__ import annotations

import logging
from typing import Generic, TypeVar

from ._constants import CR_BYTE, STX_BYTE
from ._events import BadFrame, Discarded, DiscardReason

__all__ = ["FrameSplitter", "ParserStats"]

_log = logging.getLogger("sj300_async.parser")

_STX = STX_BYTE[0]

#: What a subclass decodes a valid frame body into.
FrameT = TypeVar("FrameT")


class ParserStats:
    """Counters of everything a parser saw; all discards are counted here."""

    __slots__ = ("bad_frames", "discarded_bytes", "frames", "overlong_frames", "restarted_frames")

    def __init__(self) -> None:
        #: Valid frames yielded.
        self.frames = 0
        #: Complete frames rejected (BadFrame events).
        self.bad_frames = 0
        #: Bytes thrown away outside complete frames (Discarded events).
        self.discarded_bytes = 0
        #: Partial frames cut short by an STX.
        self.restarted_frames = 0
        #: Frames abandoned for exceeding the longest legal length.
        self.overlong_frames = 0

    def __repr__(self) -> str:
        fields = ", ".join(f"{name}={getattr(self, name)}" for name in self.__slots__)
        return f"ParserStats({fields})"


class FrameSplitter(Generic[FrameT]):
    """Splits a byte stream into STX..CR frames; subclasses decode the bodies.

    Feed it chunks of any size with :meth:`feed`; it returns the events the
    chunk completed, in stream order.
    """

    def __init__(self, max_body: int) -> None:
        #: The longest body (bytes between STX and CR) a frame may have.
        self.max_body = max_body
        self.stats = ParserStats()
        self._in_frame = False
        self._partial = bytearray()

    @property
    def buffered(self) -> int:
        """Bytes held for an incomplete frame (never more than ``max_body``)."""
        return len(self._partial)

    def reset(self) -> list[FrameT | BadFrame | Discarded]:
        """Forget any partial frame (e.g. after draining the line); return it as discarded."""
        events: list[FrameT | BadFrame | Discarded] = []
        if self._in_frame:
            self._discard(events, DiscardReason.RESTARTED, STX_BYTE + bytes(self._partial))
            self.stats.restarted_frames += 1
        self._partial.clear()
        self._in_frame = False
        return events

    def _decode_body(self, body: bytes) -> FrameT | BadFrame:
        raise NotImplementedError

    def _discard(
        self, events: list[FrameT | BadFrame | Discarded], reason: DiscardReason, data: bytes
    ) -> None:
        self.stats.discarded_bytes += len(data)
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("discarded %d bytes (%s): %s", len(data), reason.value, data.hex(" "))
        events.append(Discarded(reason, data))

    def _bad(self, event: BadFrame) -> None:
        self.stats.bad_frames += 1
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("bad frame (%s): %s", event.reason.value, event.body.hex(" "))

    def feed(self, data: bytes | bytearray | memoryview) -> list[FrameT | BadFrame | Discarded]:
        """Consume a chunk; return the events it completed (possibly none)."""
        if type(data) is not bytes:
            data = bytes(data)
        end = len(data)
        if (
            not self._in_frame
            and end >= 2
            and data[0] == _STX
            and data.find(CR_BYTE) == end - 1
            and data.find(STX_BYTE, 1) < 0
            and end - 2 <= self.max_body
        ):
            # The usual chunk: exactly one whole frame, STX first, CR last and
            # neither in between. The loop below would reach the same single
            # event; this only skips its bookkeeping.
            return [self._complete(data[1:-1])]
        events: list[FrameT | BadFrame | Discarded] = []
        pos = 0
        partial = self._partial
        max_body = self.max_body
        while pos < end:
            if not self._in_frame:
                stx = data.find(STX_BYTE, pos)
                if stx < 0:
                    self._discard(events, DiscardReason.GARBAGE, data[pos:])
                    break
                if stx > pos:
                    self._discard(events, DiscardReason.GARBAGE, data[pos:stx])
                self._in_frame = True
                pos = stx + 1
                continue
            # Search no further than the longest legal frame could reach: beyond
            # it the frame is overlong anyway, and an unbounded search would
            # make a chunk with many STX and no CR cost quadratic time.
            reach = min(end, pos + max_body + 1 - len(partial))
            cr = data.find(CR_BYTE, pos, reach)
            stop = cr if cr >= 0 else reach
            stx = data.find(STX_BYTE, pos, stop)
            limit = stx if stx >= 0 else stop
            if len(partial) + (limit - pos) > max_body:
                # Longer than any legal frame: abandon it at byte max_body + 1, as a
                # byte-by-byte feed would, and hunt for the next STX.
                cut = pos + max_body + 1 - len(partial)
                self._discard(
                    events, DiscardReason.OVERLONG, STX_BYTE + bytes(partial) + data[pos:cut]
                )
                self.stats.overlong_frames += 1
                partial.clear()
                self._in_frame = False
                pos = cut
                continue
            if stx >= 0:
                # A new frame starts before this one ended: the partial frame is lost.
                self._discard(
                    events, DiscardReason.RESTARTED, STX_BYTE + bytes(partial) + data[pos:stx]
                )
                self.stats.restarted_frames += 1
                partial.clear()
                pos = stx + 1
                continue
            if cr < 0:
                partial += data[pos:]
                break
            if partial:
                body = bytes(partial) + data[pos:cr]
                partial.clear()
            else:
                body = data[pos:cr]
            self._in_frame = False
            pos = cr + 1
            events.append(self._complete(body))
        return events

    def _complete(self, body: bytes) -> FrameT | BadFrame:
        """Decode a whole frame's body and count the outcome."""
        event = self._decode_body(body)
        if type(event) is BadFrame:
            self._bad(event)
        else:
            self.stats.frames += 1
        return event
