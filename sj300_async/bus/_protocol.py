"""The protocol adapter: one asyncio.Protocol for every transport.

It feeds received chunks to the sans-IO reply parser and hands every event
to a listener (the arbiter). It knows nothing of requests or time-outs.

Local echo
----------
RS-485 adapters without echo suppression (and device servers behind them)
hand every byte the host writes back to it, ahead of anything a drive says.
The adapter removes that echo before the parser sees the input. Three modes
(``strip_echo``; the URL's ``echo=``):

- ``None``, ``echo=auto`` (the default): find out, frame by frame. After each
  write the adapter expects that frame back; if the next bytes received are
  the frame, exactly, they are echo and removed; if anything else comes
  first, they go to the parser and the line does not echo (for now).
- ``True``, ``echo=1``: the same stripping; every expected echo that does not
  come also counts in ``BusStats.echo_mismatches`` (with ``auto`` only those
  on a line known to echo count), so a wrong ``echo=1`` shows.
- ``False``, ``echo=0``: never look; every byte goes to the parser.

The rules:

1. Only a whole, exact copy of a written frame is echo. It may arrive split
   over chunks: while the bytes received are a prefix of the frame they are
   held back; when the frame completes they are dropped and counted
   (``echo_bytes``, ``echo_frames``); at the first byte that differs, the
   held bytes and the rest of the chunk go to the parser, in order. Held
   bytes go to the parser too when the arbiter resets it after a failed
   transaction, and when the next frame is written on a line not known to
   echo. No byte is lost, only delayed until it is known not to be echo.
2. ``BusStats.echo_detected`` is True once a written frame came back, False
   once one did not (other bytes came first, or the line was drained with the
   echo still expected), None before either. One echo is enough: an exact
   copy of the frame just written can only be its echo (below). One missing
   echo makes it False again (an echo damaged by noise included).
3. One echo is expected at a time, unless the line is known to echo: then a
   frame written before the previous one's echo arrived (a late echo through
   a device server) queues behind it, since echoes come back in order.
   Without the known echo a new write replaces the expectation, whose echo
   is evidently not coming: a stale one could otherwise match a later
   drive's frame (FR-700's host ``ACK station`` is byte for byte a drive's
   ACK to a write).
4. ``auto`` goes quiet after :data:`QUIET_AFTER_MISSES` written frames in a
   row whose echo did not come: it stops expecting echoes, and costs nothing
   more than ``echo=0``. It looks again (expects the next frame's echo; one
   more miss and it is quiet again) whenever the parser discards bytes or
   rejects a frame, which is what an echo left in the input turns into
   (an SJ300 request parses as a bad frame, an FR-700 one as discarded
   bytes), and after every drain. A new connection starts looking at every
   frame. ``echo=1`` never goes quiet.

Why an exact copy of what the host wrote is always echo, never an answer (the
claim that makes ``auto`` safe; ``tests/bus/test_echo.py`` checks it against
both codecs):

- SJ300: a request is ``STX node command data BCC CR`` in ASCII digits and
  hex; the host writes nothing else. ACK, ACK-with-data and NAK answers
  carry ACK (06h) or NAK (15h), never found in a request. The data answers
  (commands 03, 04, 05) carry 104, 8 or 440 characters to a request with
  none: their body is 108, 12 or 444 characters, the request's 6. A request
  may still parse as some reply (a set-frequency request has a status
  reply's length), but never as an answer to itself: stripping such a copy
  loses at most a stray frame.
- FR-700: a request starts with ENQ, every drive frame with STX, ACK or NAK.
  The host's other two frames do look like drive frames: its acknowledgement
  after a data reply (``ACK station``, a drive's ACK exactly) and its
  re-output request (``NAK station``). No drive answers either with such a
  frame: nobody speaks after the host's ACK until the next write (which
  replaces the expectation, rule 3), and a re-output request is answered
  with the data reply again (STX).

Any other protocol runs on the same rule: ``auto`` assumes that no answer is
ever an exact copy of its request. A protocol whose answers can be (Modbus
RTU answers a register write with a copy of it) must open its buses with
``echo=0`` on a line that does not echo.

Cost on a line that does not echo: while it looks, a method call and two
``bytes.startswith`` on the first chunk after each write (an SJ300 reply
shares its first bytes with the request, so only a byte-wise comparison
tells them apart); ``echo=1`` pays that on every transaction. Quiet, the
code path is that of ``echo=0``: callgrind finds no difference beyond its
noise.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Final, Generic, Protocol, TypeVar, cast

from ..transports import BufferedReads
from ..wire import BadFrame, Discarded
from ._chunklog import ChunkLog
from ._dialect import LineParser, ReplyT
from ._stats import BusStats
from ._trace import TraceHook, TraceRecord

__all__ = ["LineListener", "LineProtocol"]

_log = logging.getLogger("sj300_async.line")

#: ``echo=auto`` stops expecting an echo of every frame after this many
#: written frames in a row whose echo did not come (rule 4).
QUIET_AFTER_MISSES: Final = 3


_ReplyT_contra = TypeVar("_ReplyT_contra", contravariant=True)


class LineListener(Protocol[_ReplyT_contra]):
    """What the adapter reports to (the arbiter)."""

    def event_received(self, event: _ReplyT_contra | BadFrame | Discarded, now: float) -> None:
        """A parser event; *now* is the loop time the chunk arrived."""

    def bytes_received(self, data: bytes, now: float) -> None:
        """A chunk arrived, as it arrived (for the quiet-time bookkeeping and the logs)."""

    def connection_lost(self, exc: BaseException | None) -> None:
        """The transport is gone; whatever waits for an answer must fail now."""


class LineProtocol(BufferedReads, Generic[ReplyT]):
    """Adapter between an asyncio transport and the sans-IO reply parser.

    A socket transport reads into the adapter's own buffer (see
    :class:`~sj300_async.transports._buffered.BufferedReads`); every other
    transport calls :meth:`data_received`.

    Args:
        strip_echo: None to find out whether the line echoes and strip what it
            does (``echo=auto``), True when it echoes (``echo=1``), False to
            never look (``echo=0``); see the module docstring.
    """

    def __init__(
        self,
        parser: LineParser[ReplyT],
        listener: LineListener[ReplyT],
        stats: BusStats,
        *,
        strip_echo: bool | None = False,
        trace: TraceHook | None = None,
        recorder: ChunkLog | None = None,
    ) -> None:
        super().__init__()
        self._parser = parser
        self._listener = listener
        self._stats = stats
        self._strip_echo = strip_echo
        # Expect the next written frame's echo (False: echo=0, or auto gone quiet).
        self._expect_echo = strip_echo is not False
        # Written frames in a row whose echo did not come (auto: rule 4).
        self._misses = 0
        # The rest of the written frame whose echo is expected (b"": none), the
        # part of it received so far (held back from the parser), and the frames
        # written after it on a line known to echo (rules 1 and 3).
        self._echo = b""
        self._held = b""
        self._echo_queue: list[bytes] = []
        self.trace = trace
        #: The line's recent traffic, kept without a trace record (Bus.recorder).
        self.recorder = recorder
        self._transport: asyncio.Transport | None = None
        self._loop = asyncio.get_running_loop()
        self._writable = asyncio.Event()
        self._writable.set()
        #: True while the transport has asked us to pause writing: a plain
        #: attribute, since the arbiter reads it before every write.
        self.write_paused = False
        #: Set when the transport hands itself over (some transports, like
        #: pyserial-asyncio's, do so a loop iteration after they are created).
        self.made: asyncio.Future[None] = self._loop.create_future()
        #: Set when the connection is lost; carries the exception (None for a clean close).
        self.lost: asyncio.Future[BaseException | None] = self._loop.create_future()

    # -- asyncio.Protocol -----------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not isinstance(): uvloop's transports implement the interface without
        # deriving from asyncio's classes.
        transport = cast(asyncio.Transport, transport)
        self._transport = transport
        if not self.made.done():
            self.made.set_result(None)

    def data_received(self, data: bytes) -> None:
        now = self._loop.time()
        self._stats.bytes_received += len(data)
        self._listener.bytes_received(data, now)
        arrived = data
        if self._echo:
            data = self._remove_echo(data)
        events = self._parser.feed(data) if data else []
        if self.trace is not None or self.recorder is not None:
            self._traced(arrived, events, now)
            return
        listener = self._listener
        for event in events:
            # _account's test written out for the commonest event, a good frame.
            if type(event) is Discarded or type(event) is BadFrame:
                self._account(event)
            elif _log.isEnabledFor(logging.DEBUG):
                _log.debug("rx %s", event)
            listener.event_received(event, now)

    def _traced(
        self, arrived: bytes, events: list[ReplyT | BadFrame | Discarded], now: float
    ) -> None:
        """data_received's delivery with a trace or a recorder: the record after the
        listener has judged the events, so it can say which it refused as early (the
        arbiter's early-frame count moved). Nothing the listener does writes at once (a
        re-output request is scheduled), so this record still precedes the next tx."""
        stats = self._stats
        early = []
        for event in events:
            refused = stats.early_frames
            if type(event) is Discarded or type(event) is BadFrame:
                self._account(event)
            elif _log.isEnabledFor(logging.DEBUG):
                _log.debug("rx %s", event)
            self._listener.event_received(event, now)
            if stats.early_frames != refused:
                early.append(event)
        if self.recorder is not None:
            self.recorder.append(now, "rx", arrived, bool(early))
        if self.trace is not None:
            self.trace(TraceRecord(now, "rx", arrived, tuple(events), tuple(early)))

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        self.write_paused = False
        self._writable.set()
        if not self.lost.done():
            self.lost.set_result(exc)
        self._listener.connection_lost(exc)

    def pause_writing(self) -> None:
        self.write_paused = True
        self._writable.clear()

    def resume_writing(self) -> None:
        self.write_paused = False
        self._writable.set()

    # -- for the arbiter --------------------------------------------------------

    @property
    def connected(self) -> bool:
        """True until the transport is lost or closed."""
        return self._transport is not None and not self._transport.is_closing()

    def write(self, frame: bytes) -> None:
        """Write a frame. The caller has checked :attr:`connected`."""
        assert self._transport is not None
        if self._expect_echo:
            if self._echo:
                self._expect_another(frame)
            else:
                self._echo = frame
        if self.recorder is not None or self.trace is not None:
            now = self._loop.time()  # one instant for both
            if self.recorder is not None:
                self.recorder.append(now, "tx", frame, False)
            if self.trace is not None:
                self.trace(TraceRecord(now, "tx", frame))
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("tx %s", frame.hex(" "))
        self._stats.bytes_written += len(frame)
        self._transport.write(frame)

    async def wait_writable(self) -> None:
        """Return when the transport's write buffer is below its high-water mark."""
        if not self._writable.is_set():
            await self._writable.wait()

    def close(self) -> None:
        """Close the transport (idempotent)."""
        if self._transport is not None:
            self._transport.close()

    def abort(self) -> None:
        """Drop the connection at once, for tests and for an unrecoverable state."""
        if self._transport is not None:
            self._transport.abort()

    def reset_parser(self) -> None:
        """Forget a partial frame (after a drain); it is counted as discarded.

        An echo still expected now is not coming: what was held back as its
        start goes to the parser first.
        """
        if self._echo:
            held = self._echo_missed()
            if held:
                self._deliver(held)
        self._look_again()
        for event in self._parser.reset():
            self._account(event)

    # -- internals ----------------------------------------------------------------

    def _remove_echo(self, data: bytes) -> bytes:
        """Remove the expected echo from *data*; return what is for the parser (rule 1)."""
        while True:
            echo = self._echo
            if data.startswith(echo):  # the whole echo (the rest of it) is here
                data = data[len(echo) :]
                self._echo_came(len(self._held) + len(echo))
                if not data or not self._echo:
                    return data
            elif echo.startswith(data):  # so far, so good: hold it back
                self._held += data
                self._echo = echo[len(data) :]
                return b""
            else:  # not our echo: every byte, held ones first, goes to the parser
                held = self._echo_missed()
                return held + data if held else data

    def _echo_came(self, size: int) -> None:
        self._misses = 0
        stats = self._stats
        stats.echo_bytes += size
        stats.echo_frames += 1
        stats.echo_detected = True
        self._held = b""
        queue = self._echo_queue
        self._echo = queue.pop(0) if queue else b""

    def _echo_missed(self) -> bytes:
        """The expected echo did not come: forget it; return the bytes held back for it."""
        stats = self._stats
        held = self._held
        if self._strip_echo or stats.echo_detected:
            stats.echo_mismatches += 1
            if _log.isEnabledFor(logging.DEBUG):
                _log.debug("echo of %s did not come", (held + self._echo).hex(" "))
        stats.echo_detected = False
        self._echo = self._held = b""
        self._echo_queue.clear()
        if self._strip_echo is None:
            self._misses += 1
            if self._misses >= QUIET_AFTER_MISSES:
                self._expect_echo = False  # quiet until something looks wrong (rule 4)
        return held

    def _look_again(self) -> None:
        """Auto, quiet: expect the next written frame's echo once more (rule 4)."""
        if self._strip_echo is None and not self._expect_echo:
            self._expect_echo = True
            self._misses = QUIET_AFTER_MISSES - 1  # one miss and it is quiet again

    def _expect_another(self, frame: bytes) -> None:
        """A frame is written while the previous one's echo is still expected (rule 3)."""
        if self._stats.echo_detected:
            self._echo_queue.append(frame)  # echoes come back in order
            return
        held = self._echo_missed()
        if held:
            self._deliver(held)
        self._echo = frame

    def _deliver(self, data: bytes) -> None:
        """Feed bytes held back as a possible echo to the parser after all."""
        now = self._loop.time()
        for event in self._parser.feed(data):
            self._account(event)
            self._listener.event_received(event, now)

    def _account(self, event: ReplyT | BadFrame | Discarded) -> None:
        # Discarded bytes and bad frames are what an echo left in the input turns
        # into: a quiet auto looks again (rule 4).
        if type(event) is Discarded:
            self._stats.discarded_bytes += len(event.data)
            self._look_again()
        elif type(event) is BadFrame:
            self._stats.bad_frames += 1
            self._look_again()
        elif _log.isEnabledFor(logging.DEBUG):
            _log.debug("rx %s", event)  # discards and bad frames are logged by the parser
