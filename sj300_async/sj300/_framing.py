"""The STX..CR frame splitter shared by the reply parser and the request parser.

State machine (the whole of it lives in :meth:`FrameSplitter._run`)::

    HUNTING --STX--> IN_FRAME --CR--> (frame complete) --> HUNTING
       ^  \\--other bytes: Discarded(GARBAGE)
       |     IN_FRAME --STX--> Discarded(RESTARTED), stay IN_FRAME (new frame)
       \\---- IN_FRAME --more than max_body bytes--> Discarded(OVERLONG) --> HUNTING

Rather than stepping byte by byte, each state searches the chunk with
``bytes.find`` for the next byte that can change it (STX when hunting; CR or
STX inside a frame). The buffer of an incomplete frame never exceeds
``max_body`` bytes: memory is bounded whatever the line sends.

:meth:`FrameSplitter.feed` takes a shortcut for a clean line. Every CR leaves
the machine HUNTING (it ends a frame, or is garbage while hunting), so a
chunk split at its CRs is a run of pieces whose starting state is known:
the first starts where the last chunk left off, the others HUNTING. A piece
that is a whole frame on its own (STX, no other STX, at most ``max_body``
bytes) is decoded at once, and one that continues the partial frame without
an STX is appended to it; either is exactly what the machine would do. Any
other piece runs through the machine. A chunk that is exactly one whole
frame, the commonest on a fast line, skips even the split, and so does a
chunk inside a frame that neither ends it nor starts another.
"""

from __future__ import annotations

import logging
from typing import Generic, TypeVar

from ..wire import BadFrame, Discarded, DiscardReason, ParserStats
from ._constants import CR_BYTE, STX_BYTE

__all__ = ["FrameSplitter"]

_log = logging.getLogger("sj300_async.parser")

_STX = STX_BYTE[0]
_CR = CR_BYTE[0]

#: What a subclass decodes a valid frame body into.
FrameT = TypeVar("FrameT")


class FrameSplitter(Generic[FrameT]):
    """Splits a byte stream into STX..CR frames; subclasses decode the bodies.

    Feed it chunks of any size with :meth:`feed`; it returns the events the
    chunk completed, in stream order.
    """

    def __init__(self, max_body: int) -> None:
        #: The longest body (bytes between STX and CR) a frame may have.
        self.max_body = max_body
        self.stats = ParserStats()
        # The state: None while HUNTING; IN_FRAME, the bytes received since the
        # frame's STX (never an STX or CR among them, never more than max_body).
        self._partial: bytes | None = None

    @property
    def buffered(self) -> int:
        """Bytes held for an incomplete frame (never more than ``max_body``)."""
        return 0 if self._partial is None else len(self._partial)

    def reset(self) -> list[FrameT | BadFrame | Discarded]:
        """Forget any partial frame (e.g. after draining the line); return it as discarded."""
        events: list[FrameT | BadFrame | Discarded] = []
        if self._partial is not None:
            self._discard(events, DiscardReason.RESTARTED, STX_BYTE + self._partial)
            self.stats.restarted_frames += 1
        self._partial = None
        return events

    def _decode_body(self, body: bytes) -> FrameT | BadFrame:
        """Decode the body of a complete frame (STX and CR stripped).

        Return the frame, or a BadFrame that has been passed to :meth:`_bad`.
        """
        raise NotImplementedError

    def _discard(
        self, events: list[FrameT | BadFrame | Discarded], reason: DiscardReason, data: bytes
    ) -> None:
        self.stats.discarded_bytes += len(data)
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("discarded %d bytes (%s): %s", len(data), reason.value, data.hex(" "))
        events.append(Discarded(reason, data))

    def _bad(self, event: BadFrame) -> None:
        """Count and log a bad frame (called by :meth:`_decode_body`).

        The splitter counts every body it decodes as a frame (cheaper than
        asking each event its type); this moves a bad one to ``bad_frames``.
        Both counters are right again by the time :meth:`feed` returns.
        """
        stats = self.stats
        stats.frames -= 1
        stats.bad_frames += 1
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("bad frame (%s): %s", event.reason.value, event.body.hex(" "))

    def feed(self, data: bytes | bytearray | memoryview) -> list[FrameT | BadFrame | Discarded]:
        """Consume a chunk; return the events it completed (possibly none)."""
        if type(data) is not bytes:
            data = bytes(data)
        partial = self._partial
        if partial is None:
            # The commonest chunk on a TCP bridge or a fast line: one whole frame
            # and nothing else (its only CR last, an STX first and nowhere else).
            # Decoded here, without splitting: fewer bytecodes a reply
            # (benchmarks.profile_tcp counts them).
            # (`in` with an int: far cheaper than a method call such as find.)
            if data and data[-1] == _CR and data[0] == _STX:
                whole = data[1:-1]
                if _CR not in whole and _STX not in whole and len(whole) <= self.max_body:
                    self.stats.frames += 1
                    return [self._decode_body(whole)]
        elif _CR not in data and _STX not in data:
            # More of a frame and not its end (a slow line's or a USB adapter's
            # chunk): the frame grows, if not past the longest legal one.
            partial += data
            if len(partial) <= self.max_body:
                self._partial = partial
                return []
            partial = self._partial
        events: list[FrameT | BadFrame | Discarded] = []
        max_body = self.max_body
        # The shortcut of the module docstring, up to the first piece that needs
        # the machine: the machine takes the rest of the chunk from there (so
        # that, e.g., garbage with CRs in it stays one Discarded event). Note
        # `_STX in body`: testing for an int is much cheaper than for a bytes.
        tail = data  # what follows the last CR: the whole chunk if it has none
        if _CR in data:
            pieces = data.split(CR_BYTE)
            tail = pieces.pop()
            for piece in pieces:  # each ended by a CR
                if partial is not None:  # IN_FRAME: the CR ends the frame
                    body = partial + piece
                elif piece and piece[0] == _STX:  # HUNTING: a whole frame, perhaps
                    body = piece[1:]
                else:
                    body = None
                if body is None or _STX in body or len(body) > max_body:
                    partial = self._run_rest(pieces, tail, partial, events)
                    tail = b""
                    break
                partial = None
                events.append(self._decode_body(body))
            else:
                self.stats.frames += len(events)  # one per piece
        if tail:  # no CR in it: a frame's beginning, or more of it
            if partial is None and tail[0] != _STX:
                partial = self._run(tail, partial, events)
            else:
                body = tail[1:] if partial is None else partial + tail
                if _STX in body or len(body) > max_body:
                    partial = self._run(tail, partial, events)
                else:
                    partial = body
        self._partial = partial
        return events

    def _run_rest(
        self,
        pieces: list[bytes],
        tail: bytes,
        partial: bytes | None,
        events: list[FrameT | BadFrame | Discarded],
    ) -> bytes | None:
        """Hand the chunk to the machine from the piece the shortcut stopped at."""
        decoded = len(events)  # one per piece so far
        self.stats.frames += decoded
        return self._run(CR_BYTE.join([*pieces[decoded:], tail]), partial, events)

    def _run(
        self, data: bytes, partial: bytes | None, events: list[FrameT | BadFrame | Discarded]
    ) -> bytes | None:
        """Run the state machine over *data* from state *partial*; return the new state."""
        max_body = self.max_body
        end = len(data)
        pos = 0
        while True:
            if partial is None:  # HUNTING
                if pos >= end:
                    break
                stx = data.find(STX_BYTE, pos)
                if stx < 0:
                    self._discard(events, DiscardReason.GARBAGE, data[pos:])
                    break
                if stx > pos:
                    self._discard(events, DiscardReason.GARBAGE, data[pos:stx])
                partial = b""
                pos = stx + 1
            # IN_FRAME. Search no further than the longest legal frame could
            # reach: beyond it the frame is overlong anyway, and an unbounded
            # search would make a chunk with many STX and no CR cost quadratic
            # time. (find() treats an end past the chunk as the chunk's end.)
            reach = pos + max_body + 1 - len(partial)
            cr = data.find(CR_BYTE, pos, reach)
            stx = data.find(STX_BYTE, pos, reach if cr < 0 else cr)
            if stx >= 0:
                # A new frame starts before this one ended: the partial frame is lost.
                self._discard(events, DiscardReason.RESTARTED, STX_BYTE + partial + data[pos:stx])
                self.stats.restarted_frames += 1
                partial = b""
                pos = stx + 1
            elif cr >= 0:  # the frame is complete (and, within reach, not too long)
                self.stats.frames += 1
                events.append(self._decode_body(partial + data[pos:cr]))
                partial = None
                pos = cr + 1
            elif reach <= end:
                # max_body + 1 bytes and no CR: longer than any legal frame. Abandon
                # it at that byte, as a byte-by-byte feed would, and hunt for an STX.
                self._discard(events, DiscardReason.OVERLONG, STX_BYTE + partial + data[pos:reach])
                self.stats.overlong_frames += 1
                partial = None
                pos = reach
            else:  # the chunk ends inside the frame
                partial += data[pos:]
                break
        return partial
