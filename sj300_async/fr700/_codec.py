"""The FR-700 frame codec: line options, the sum check, and every frame's bytes.

Sans-IO and pure. Every encoder validates before it produces a byte and
raises :class:`~sj300_async.LocalProtocolError` for anything the protocol
does not allow, so a bad request never reaches the wire.

Request layouts (the reference's formats; ``[wait]`` only with the
waiting-time field on, the terminator only when the line uses one)::

    A   ENQ station(2) instruction(2) [wait(1)] data(4) sum(2) [CR[LF]]
    A1  ENQ station(2) instruction(2) [wait(1)] data(2) sum(2) [CR[LF]]
    A2  ENQ station(2) "F0" [wait(1)] send(1) receive(1) data1(4) data2(4) sum(2) [CR[LF]]
    B   ENQ station(2) instruction(2) [wait(1)] sum(2) [CR[LF]]

The sum check is the low byte of the arithmetic sum of the characters from
the first station character through the last data character (the waiting
time included), as two upper-case hex characters.

Decisions where the reference is silent:

- Hex is upper case, as the reference lists only 0-9 and A-F: the host
  writes it so, and reads station numbers and NAK codes only so (ACK and
  NAK frames carry no sum to catch a damaged character). Only the sum of a
  data reply is read in either case, as the SJ300 parser reads its BCC: the
  sum itself proves the frame.
- Which writes carry two digits (A1) is a property of the instruction
  (:data:`~sj300_async.fr700.A1_INSTRUCTIONS`); the raw encoder accepts two
  or four digits for any write, so an instruction this library does not
  know can still be sent with the width its manual gives.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from ..wire import LocalProtocolError
from ._codes import ACK, ENQ, ETX, NAK, STX, Fr700Instruction, Fr700NakCode

__all__ = [
    "DEFAULT_LINE_OPTIONS",
    "MAX_REPLY_DATA",
    "MAX_STATION",
    "MIN_STATION",
    "Fr700LineOptions",
    "encode_ack",
    "encode_data_reply",
    "encode_host_ack",
    "encode_nak",
    "encode_reoutput_request",
    "encode_request",
    "instruction_wire",
    "parse_station",
    "station_wire",
    "sum_check",
    "terminator_bytes",
]

MIN_STATION: Final = 0
MAX_STATION: Final = 31
#: The longest data field of a reply: the model name (format E3).
MAX_REPLY_DATA: Final = 20

_TERMINATORS: Final = {"": b"", "\r": b"\r", "\r\n": b"\r\n"}
_HEX_UPPER: Final = re.compile(rb"[0-9A-F]*")
_STATIONS: Final = {b"%02X" % n: n for n in range(MIN_STATION, MAX_STATION + 1)}
_STATION_WIRE: Final = {n: b"%02X" % n for n in range(MIN_STATION, MAX_STATION + 1)}
_ENQ: Final = bytes((ENQ,))
_STX: Final = bytes((STX,))
_ETX: Final = bytes((ETX,))
_ACK: Final = bytes((ACK,))
_NAK: Final = bytes((NAK,))


def terminator_bytes(terminator: str | bytes) -> bytes:
    """A terminator given as str or bytes, checked: ``b""``, ``b"\\r"`` or ``b"\\r\\n"``.

    Raises:
        LocalProtocolError: anything else.
    """
    text = terminator
    if isinstance(text, bytes | bytearray):
        text = bytes(text).decode("latin-1")
    if not isinstance(text, str) or text not in _TERMINATORS:
        raise LocalProtocolError(f"terminator must be '', '\\r' or '\\r\\n', got {terminator!r}")
    return _TERMINATORS[text]


@dataclass(frozen=True, slots=True)
class Fr700LineOptions:
    """How frames look on this line; host and drives must agree (Pr.123 / Pr.124).

    Args:
        wait_field: requests carry the one-character waiting-time field (the
            drive's Pr.123 = 9999, its factory setting).
        wait_time_digit: the waiting time the host asks for, 0..15 (x 10 ms).
        terminator: what ends every frame in both directions: ``b""`` (none),
            ``b"\\r"`` (the factory setting) or ``b"\\r\\n"``
            (:func:`terminator_bytes` converts a str).

    Raises:
        LocalProtocolError: a value the protocol does not allow.
    """

    wait_field: bool = True
    wait_time_digit: int = 0
    terminator: bytes = b"\r"

    def __post_init__(self) -> None:
        if not isinstance(self.wait_field, bool):
            raise LocalProtocolError(f"wait_field must be a bool, got {self.wait_field!r}")
        digit = self.wait_time_digit
        if isinstance(digit, bool) or not isinstance(digit, int) or not 0 <= digit <= 15:
            raise LocalProtocolError(f"wait_time_digit is 0..15 (x 10 ms), got {digit!r}")
        # Frozen: a str is normalized to bytes once, here.
        object.__setattr__(self, "terminator", terminator_bytes(self.terminator))

    @property
    def wait_s(self) -> float:
        """The waiting time the requests ask for (0 without the field: the drive's own)."""
        return self.wait_time_digit * 0.01 if self.wait_field else 0.0


DEFAULT_LINE_OPTIONS: Final = Fr700LineOptions()


def sum_check(chars: bytes) -> bytes:
    """The two upper-case hex characters of the sum check of *chars*.

    >>> sum_check(b"01E1107AD")
    b'F4'
    """
    return b"%02X" % (sum(chars) & 0xFF)


def station_wire(station: int) -> bytes:
    """The two hex characters of *station* (``b"00"``..``b"1F"``).

    Raises:
        LocalProtocolError: *station* is not an int 0..31.
    """
    if isinstance(station, bool) or not isinstance(station, int):
        raise LocalProtocolError(f"station must be an int 0..31, got {station!r}")
    wire = _STATION_WIRE.get(station)
    if wire is None:
        raise LocalProtocolError(f"station must be 0..31, got {station!r}")
    return wire


def parse_station(chars: bytes) -> int | None:
    """The station of two upper-case hex characters 00..1F, or None."""
    return _STATIONS.get(chars)


def instruction_wire(instruction: int) -> bytes:
    """The two hex characters of an instruction code 0x00..0xFF.

    Raises:
        LocalProtocolError: not an int 0..255.
    """
    if isinstance(instruction, bool) or not isinstance(instruction, int):
        raise LocalProtocolError(f"instruction code must be an int, got {instruction!r}")
    if not 0 <= instruction <= 0xFF:
        raise LocalProtocolError(f"instruction code must be H00..HFF, got {instruction!r}")
    return b"%02X" % instruction


def _check_data(instruction: int, data: bytes) -> None:
    if not isinstance(data, bytes):
        raise LocalProtocolError(f"data must be bytes, got {type(data).__name__}")
    if not _HEX_UPPER.fullmatch(data):
        raise LocalProtocolError(f"data must be upper-case hex digits, got {data!r}")
    name = f"H{instruction:02X}"
    if instruction < 0x80:
        if data:
            raise LocalProtocolError(f"{name} is a read (format B): it takes no data, got {data!r}")
    elif instruction == Fr700Instruction.MULTI_COMMAND:
        if len(data) != 10:
            raise LocalProtocolError(
                f"HF0 takes send type, receive type and two 4-digit data (10 digits), got {data!r}"
            )
    elif len(data) not in (2, 4):
        raise LocalProtocolError(f"{name} is a write: it takes 2 or 4 hex digits, got {data!r}")


def encode_request(
    station: int,
    instruction: int,
    data: bytes = b"",
    *,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
) -> bytes:
    """The whole request frame, ENQ through the terminator.

    Args:
        station: 0..31.
        instruction: H00..H7F read (format B, no data), H80..HFF write (2 or 4
            hex digits), HF0 multi-command (10 digits).
        data: upper-case hex digits.

    Raises:
        LocalProtocolError: the protocol does not allow this request (nothing is produced).

    >>> encode_request(1, 0xE1, b"07AD", options=Fr700LineOptions(wait_time_digit=1))
    b'\\x0501E1107ADF4\\r'
    """
    body = station_wire(station) + instruction_wire(instruction)
    _check_data(instruction, data)
    if options.wait_field:
        body += b"%X" % options.wait_time_digit
    body += data
    return _ENQ + body + sum_check(body) + options.terminator


# -- replies (the drive's side: the simulator, tests, traces) -------------------------


def encode_data_reply(station: int, data: bytes, terminator: bytes = b"\r") -> bytes:
    """Formats E, E1, E2, E3, C1: ``STX station data ETX sum [terminator]``.

    Raises:
        LocalProtocolError: bad station, or data empty, longer than 20 characters
            or not printable ASCII.
    """
    if not isinstance(data, bytes) or not 1 <= len(data) <= MAX_REPLY_DATA:
        raise LocalProtocolError(f"reply data must be 1..20 bytes, got {data!r}")
    if any(not 0x20 <= b <= 0x7E for b in data):
        raise LocalProtocolError(f"reply data must be printable ASCII, got {data!r}")
    body = station_wire(station) + data
    return _STX + body + _ETX + sum_check(body) + terminator


def encode_ack(station: int, terminator: bytes = b"\r") -> bytes:
    """Format C from the drive: ``ACK station [terminator]``."""
    return _ACK + station_wire(station) + terminator


def encode_nak(station: int, code: Fr700NakCode | int, terminator: bytes = b"\r") -> bytes:
    """Format D: ``NAK station code [terminator]``.

    Raises:
        LocalProtocolError: bad station, or *code* not 0..15.
    """
    if isinstance(code, bool) or not isinstance(code, int) or not 0 <= code <= 0xF:
        raise LocalProtocolError(f"a NAK code is one hex digit 0..F, got {code!r}")
    return _NAK + station_wire(station) + b"%X" % code + terminator


def encode_host_ack(station: int, terminator: bytes = b"\r") -> bytes:
    """Format C from the host, after good read data: ``ACK station [terminator]``."""
    return encode_ack(station, terminator)


def encode_reoutput_request(station: int, terminator: bytes = b"\r") -> bytes:
    """Format F from the host, after damaged read data: ``NAK station [terminator]``."""
    return _NAK + station_wire(station) + terminator
