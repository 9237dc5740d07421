"""``--trace``: every frame a command sends and receives, on stderr, timed and decoded.

One line per record of the bus's trace hook (:class:`~sj300_async.bus.TraceRecord`)::

       0.002 → tx  02 30 31 30 34 30 35 0D  node 01 command 04 read status
       0.004 ← rx  02 30 31 30 30 ... 0D  node 01 data 000100

- the time: seconds since the command opened its bus, to the millisecond;
- the direction: ``→ tx`` what the host wrote, ``← rx`` what arrived;
- the bytes in hex, exactly as they crossed the line: an rx line is a chunk
  as it arrived, so a reply split across chunks shows as several lines (the
  one that completes it carries its meaning, the others ``…``), and a local
  echo shows as received;
- the meaning. rx: every event the chunk completed, ``; ``-separated: a
  reply as the protocol's dialect describes it (:meth:`Dialect.describe
  <sj300_async.bus.Dialect.describe>`), a bad frame or discarded bytes
  with the parser's reason. An answer the bus refused because it came
  sooner than the URL's baud rate allows (a peer faster than the line it
  claims: a test double, an emulator over TCP) is followed by
  ``[refused: sooner than …; baudrate=0 in the URL turns the check off]``,
  so the trace shows the answers the call's time-out says it refused. tx:
  the frame read back the way a drive reads it, by what the protocol's
  profile provides
  (:meth:`~sj300_async.profiles.Profile.request_describer`: SJ300's and
  FR-700's run their own request parser): node, command and its name,
  data. A parser, not the request object, because the hook sees bytes
  only; a frame is short, so a fresh parser per frame costs nothing and
  carries no state between frames. A protocol without one (or without a
  profile) shows its frame's characters, control bytes named
  (``<STX>01<CR>``).

Tracing never breaks a command: a frame that cannot be decoded prints its
hex and why.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, Final, TextIO

from ..bus import Dialect, TraceRecord
from ..profiles import frame_text, get_profile
from ..wire import BadFrame, Discarded, LocalProtocolError

__all__ = ["FrameTracer", "describe_bytes", "request_describer"]

_ARROWS: Final = {"tx": "→ tx", "rx": "← rx"}
#: After an answer the bus refused as too early (TraceRecord.early): why, and the fix,
#: as the call's ReplyTimeoutError says it.
EARLY_MARK: Final = (
    "[refused: sooner than the URL's baud rate allows; baudrate=0 in the URL turns the check off]"
)


class FrameTracer:
    """A trace hook printing one line per record (see the module docstring).

    Args:
        dialect: the bus's protocol, which decodes the frames.
        origin: the event-loop time that shows as 0.000.
        stream: where lines go; None: ``sys.stderr`` looked up at each line,
            so rich's live displays, which redirect it, keep their place.
    """

    def __init__(
        self, dialect: Dialect[Any, Any], origin: float, stream: TextIO | None = None
    ) -> None:
        self._dialect = dialect
        self._origin = origin
        self._stream = stream
        self._describe_request = request_describer(dialect)

    def __call__(self, record: TraceRecord) -> None:
        print(self.line(record), file=self._stream or sys.stderr, flush=True)

    def line(self, record: TraceRecord) -> str:
        """The record as one line: time, direction, hex, meaning."""
        try:
            if record.direction == "tx":
                meaning = self._describe_request(record.data)
            else:
                meaning = "; ".join(self._rx_event(e, record.early) for e in record.events)
                meaning = meaning or "…"
        except Exception as exc:  # a hook must not raise into the protocol
            meaning = f"(not decoded: {type(exc).__name__}: {exc})"
        elapsed = record.timestamp - self._origin
        arrow = _ARROWS.get(record.direction, record.direction)
        return f"{elapsed:8.3f} {arrow}  {record.data.hex(' ').upper()}  {meaning}"

    def _rx_event(self, event: object, early: tuple[object, ...]) -> str:
        if any(event is e for e in early):
            return f"{self._event(event)} {EARLY_MARK}"
        return self._event(event)

    def _event(self, event: object) -> str:
        if isinstance(event, BadFrame):
            node = "" if event.node is None else f" from node {event.node:02d}"
            return f"bad frame{node}: {event.reason.value}"
        if isinstance(event, Discarded):
            return f"discarded {len(event.data)} byte(s): {event.reason.value}"
        return self._dialect.describe(event)


def request_describer(dialect: Dialect[Any, Any]) -> Callable[[bytes], str]:
    """What turns a frame the host wrote into words, for *dialect*'s protocol."""
    try:
        describe = get_profile(dialect.name).request_describer(dialect)
    except LocalProtocolError:  # a protocol without a profile
        describe = None
    return describe_bytes if describe is None else describe


def describe_bytes(data: bytes) -> str:
    """*data* as text: printable ASCII as is, control bytes by name, the rest as ``.``."""
    return frame_text(data)
