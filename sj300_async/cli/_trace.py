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
  with the parser's reason. tx: the frame read back the way a drive reads
  it, by the protocol's own request parser (SJ300
  :class:`~sj300_async.sj300.RequestParser`, FR-700 the simulator's
  :class:`~sj300_async.simulator.fr700.RequestParser`): node, command and
  its name, data. The parser, not the request object, because the hook sees
  bytes only; a frame is short, so a fresh parser per frame costs nothing
  and carries no state between frames. A protocol without a request parser
  here (one registered by a user) shows its frame's characters, control
  bytes named (``<STX>01<CR>``).

Tracing never breaks a command: a frame that cannot be decoded prints its
hex and why.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, Final, TextIO

from ..bus import Dialect, TraceRecord
from ..fr700._codes import Fr700Instruction
from ..fr700._dialect import Fr700Dialect
from ..sj300._constants import BROADCAST
from ..sj300._dialect import SJ300Dialect
from ..wire._events import BadFrame, Discarded

__all__ = ["FrameTracer", "describe_bytes", "request_describer"]

_ARROWS: Final = {"tx": "→ tx", "rx": "← rx"}
_CONTROL: Final = {
    0x02: "<STX>",
    0x03: "<ETX>",
    0x05: "<ENQ>",
    0x06: "<ACK>",
    0x0A: "<LF>",
    0x0D: "<CR>",
    0x15: "<NAK>",
}


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
                meaning = "; ".join(self._event(e) for e in record.events) or "…"
        except Exception as exc:  # a hook must not raise into the protocol
            meaning = f"(not decoded: {type(exc).__name__}: {exc})"
        elapsed = record.timestamp - self._origin
        arrow = _ARROWS.get(record.direction, record.direction)
        return f"{elapsed:8.3f} {arrow}  {record.data.hex(' ').upper()}  {meaning}"

    def _event(self, event: object) -> str:
        if isinstance(event, BadFrame):
            node = "" if event.node is None else f" from node {event.node:02d}"
            return f"bad frame{node}: {event.reason.value}"
        if isinstance(event, Discarded):
            return f"discarded {len(event.data)} byte(s): {event.reason.value}"
        return self._dialect.describe(event)


def request_describer(dialect: Dialect[Any, Any]) -> Callable[[bytes], str]:
    """What turns a frame the host wrote into words, for *dialect*'s protocol."""
    if isinstance(dialect, SJ300Dialect):
        return _sj300_request
    if isinstance(dialect, Fr700Dialect):
        wait_field = dialect.options.wait_field
        terminator = dialect.options.terminator

        def fr700(frame: bytes) -> str:
            return _fr700_request(frame, wait_field=wait_field, terminator=terminator)

        return fr700
    return describe_bytes


def describe_bytes(data: bytes) -> str:
    """*data* as text: printable ASCII as is, control bytes by name, the rest as ``.``."""
    return "".join(_CONTROL.get(b, chr(b) if 0x20 <= b < 0x7F else ".") for b in data)


def _sj300_request(frame: bytes) -> str:
    from ..sj300._request_parser import RequestParser
    from ..sj300._requests import Request

    parts = []
    for event in RequestParser().feed(frame):
        if isinstance(event, Request):
            who = "broadcast" if event.node == BROADCAST else f"node {event.node:02d}"
            name = event.command.name.lower().replace("_", " ")
            text = f"{who} command {event.command.wire.decode()} {name}"
            parts.append(f"{text} {event.data.decode('ascii', 'replace')}" if event.data else text)
        elif isinstance(event, BadFrame):
            parts.append(f"bad request: {event.reason.value}")
        else:
            parts.append(f"discarded {len(event.data)} byte(s): {event.reason.value}")
    return "; ".join(parts) or describe_bytes(frame)


def _fr700_request(frame: bytes, *, wait_field: bool, terminator: bytes) -> str:
    from ..simulator.fr700 import BadRequest, HostAnswer, HostRequest, RequestParser

    parts = []
    for event in RequestParser(wait_field=wait_field, terminator=terminator).feed(frame):
        if isinstance(event, HostRequest):
            code = event.instruction
            text = f"station {event.station:02d} instruction H{code:02X} {_instruction(code)}"
            parts.append(f"{text} {event.data.decode('ascii', 'replace')}" if event.data else text)
        elif isinstance(event, HostAnswer):
            answer = "NAK: send the data again" if event.reoutput else "ACK: data received"
            parts.append(f"station {event.station:02d} host {answer}")
        elif isinstance(event, BadRequest):
            parts.append(f"bad request: {event.code.description}")
        else:
            parts.append(f"discarded {len(event.data)} byte(s): {event.reason.value}")
    # Without a terminator a frame ends by its length: the parser may want more.
    return "; ".join(parts) or describe_bytes(frame)


def _instruction(code: int) -> str:
    """An FR-700 instruction's name; the parameter ranges by their first code's."""
    try:
        name = Fr700Instruction(code).name
    except ValueError:
        if code <= 0x63:  # H00..H63: parameter offsets
            name = Fr700Instruction.READ_PARAMETER.name
        elif 0x74 <= code <= 0x77:
            name = Fr700Instruction.FAULT_HISTORY.name
        elif 0x80 <= code <= 0xE3:
            name = Fr700Instruction.WRITE_PARAMETER.name
        else:
            return "(unnamed)"
    return name.lower().replace("_", " ")
