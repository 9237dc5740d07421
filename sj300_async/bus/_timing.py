"""How long to wait for a reply, and how long the line must rest between transactions.

Sans-IO arithmetic from the line settings; the arbiter applies it.

Response time-out = request wire time + the drive's wait time (C078)
+ reply wire time + margin. The margin covers the drive's own processing
time and, for a TCP bridge, the network; it is the one number a user
normally tunes. A fixed time-out can replace the whole sum.

Guard interval: after every reply the line may rest ``guard_chars``
character times, counted from the reply's arrival. By default it does not
(0 characters), a decision: the SJ300 protocol sets no silence between a
reply and the next request (frames are delimited by STX and CR, as Modbus
ASCII's are, which needs no gap either), and a drive's RS-485 driver
releases the line within microseconds of its last stop bit, sooner than any
host turns around (a USB adapter alone takes longer). Every character of
rest is about 1.4 % of a status/monitor poll's line time, which the default
should not give away. A line with slow repeaters, isolators or
direction-switching converters sets ``guard_chars`` (1 to 3.5 is usual);
note that asyncio's default event loop waits in whole milliseconds, so a
shorter rest costs about a millisecond. After a broadcast nobody answers,
but every drive is busy for its processing time: the host waits the
broadcast's own wire time plus ``broadcast_processing_s``.

Drain after a failure: when a transaction ends without its answer (time-out,
transport error, cancellation), a reply may still be on its way. Nothing is
sent until the line has been quiet for the failed transaction's whole
response time-out (at least the guard interval); every byte that arrives
meanwhile restarts the quiet period and is discarded and counted;
``drain_max_s`` bounds a babbling line. A reply later than that (more than
about twice its time-out) is caught by the sync that the arbiter sends to
a node after a time-out or a corrupted answer (see :mod:`._arbiter`), up
to :data:`LATE_REPLY_HORIZON` time-outs after the failure.

Plausibility floor: no genuine answer can arrive sooner than the request's
own wire time plus the shortest reply's, at the fastest line the drives can
run (``plausible_baudrate``, or the line's own speed if faster), 10 bits a
character, less 5 % for clock tolerance. A frame shaped like the answer
that arrives sooner (a duplicate of the previous reply, a stray) is not
taken as the answer. The floor is 0 on an instant line.

Time-outs and deadlines: ``fixed_timeout_s`` (``open_bus(timeout=...)``)
or the computed sum is the time-out of one *attempt*; a call makes up to
``retries + 1`` attempts, with a drain between them, so a silent drive
fails after about ``(2 x attempts - 1) x timeout``. ``call_deadline_s``
(``open_bus(deadline=...)``) bounds the whole call: no attempt starts once
it has passed (an attempt already on the line runs to its own time-out),
and the call fails with the last attempt's error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..wire import LineSettings, LocalProtocolError

if TYPE_CHECKING:
    from ._dialect import LineRequest

__all__ = ["LATE_REPLY_HORIZON", "BusTiming"]

#: How late a reply may come, in response time-outs after its attempt failed,
#: and still be recognised (the arbiter's resync remembers a failed request
#: this long; its fallback drain lasts this long).
LATE_REPLY_HORIZON = 5.0
#: Bits of the shortest character any drive sends (start, 7 data, parity or
#: a second stop bit, stop; 8N1 too), for the plausibility floor.
_FLOOR_BITS_PER_CHAR = 10
#: The floor allows for clocks 5 % fast.
_FLOOR_TOLERANCE = 0.95


def _finite_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True, slots=True)
class BusTiming:
    """Timing policy of one bus. Every field is in seconds unless named otherwise.

    A call's time: ``fixed_timeout_s`` (or the computed sum) is the time-out
    of one *attempt*; a call makes up to ``retries + 1`` attempts, with a
    drain of at least one time-out of quiet before each retry, so a silent
    drive fails after about ``(2 x attempts - 1) x timeout`` (3 attempts of
    0.5 s: about 2.5 s). ``call_deadline_s`` bounds the whole call instead:
    no attempt starts once it has passed. The ``ReplyTimeoutError`` states
    the attempts, their time-out and the whole time.
    """

    #: Added to the computed wire and wait times: drive processing, network, scheduling.
    margin_s: float = 0.05
    #: If set, the response time-out of every request, replacing the computed sum.
    fixed_timeout_s: float | None = None
    #: Rest after every reply, in character times of the line, counted from the
    #: reply's arrival (see the module docstring for why the default is none).
    #: The 3.5-character silence of Modbus RTU is a framing rule that this
    #: STX..CR-delimited protocol does not need.
    guard_chars: float = 0.0
    #: Rest after a broadcast, on top of its wire time.
    broadcast_processing_s: float = 0.01
    #: Upper bound of a drain, so a line that never goes quiet cannot stall the bus.
    drain_max_s: float = 5.0
    #: The fastest line the drives can run, in baud (both built-in protocols
    #: top out at 19200): the plausibility floor assumes the line runs at this
    #: speed or the line's own, whichever is faster, so a line declared slower
    #: than it runs cannot make a genuine answer look too early.
    plausible_baudrate: int = 19200
    #: If set, the longest a call may take, in seconds, all its attempts and
    #: drains together: no attempt starts after it (one already on the line
    #: runs to its time-out), and the call fails with the last attempt's
    #: error (``ReplyTimeoutError`` if none was made). None: only the number
    #: of attempts bounds a call.
    call_deadline_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("margin_s", "guard_chars", "broadcast_processing_s", "drain_max_s"):
            value = getattr(self, name)
            if not _finite_number(value) or value < 0:
                raise LocalProtocolError(f"{name} must be a finite number >= 0, got {value!r}")
        timeout = self.fixed_timeout_s
        if timeout is not None and (not _finite_number(timeout) or timeout <= 0):
            # An infinite time-out is the hang a time-out exists to prevent.
            raise LocalProtocolError(f"timeout must be a finite number > 0, got {timeout!r}")
        deadline = self.call_deadline_s
        if deadline is not None and (not _finite_number(deadline) or deadline <= 0):
            raise LocalProtocolError(f"deadline must be a finite number > 0, got {deadline!r}")
        baud = self.plausible_baudrate
        if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
            raise LocalProtocolError(f"plausible_baudrate must be an int > 0, got {baud!r}")

    def response_timeout(
        self, request: LineRequest, line: LineSettings, wait_s: float, reply_length: int
    ) -> float:
        """Seconds from the write of *request* until its answer must have arrived.

        Args:
            wait_s: the device's wait and processing time for this request.
            reply_length: characters of the longest reply it can get.
        """
        if self.fixed_timeout_s is not None:
            return self.fixed_timeout_s
        wire = line.wire_time_s(len(request.frame) + reply_length)
        return wire + wait_s + self.margin_s

    def answer_floor(self, request: LineRequest, line: LineSettings, shortest_reply: int) -> float:
        """Seconds from the write of *request* before which no genuine answer can arrive.

        The request's and the shortest reply's wire time at the faster of the
        line's speed and :attr:`plausible_baudrate`, 10 bits a character, less
        5 %; 0 on an instant line (baud rate 0).

        Args:
            shortest_reply: characters of the shortest reply the request can get.
        """
        if not line.baudrate:
            return 0.0
        baud = max(line.baudrate, self.plausible_baudrate)
        chars = len(request.frame) + shortest_reply
        return chars * _FLOOR_BITS_PER_CHAR / baud * _FLOOR_TOLERANCE

    def guard(self, line: LineSettings) -> float:
        """Seconds the line rests after a reply."""
        return self.guard_chars * line.char_time_s

    def after_broadcast(self, request: LineRequest, line: LineSettings) -> float:
        """Seconds the line rests after a broadcast was written."""
        return line.wire_time_s(len(request.frame)) + self.broadcast_processing_s

    def drain_quiet(self, failed_timeout: float, line: LineSettings) -> float:
        """Quiet time required after a failed transaction before the next request."""
        return max(failed_timeout, self.guard(line))
