"""Building request frames: validation, encoding, and typed builders.

Every request passes :func:`validate_request` before a byte is produced, so
a request that the protocol does not allow never reaches the wire. The typed
builders (:func:`run`, :func:`set_frequency`, ...) sit on top and format the
digits, so no caller has to.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from ..wire import Direction, LocalProtocolError
from ._bcc import bcc
from ._commands import Command, RequestData
from ._constants import BROADCAST, CR_BYTE, MAX_NODE, MIN_NODE, STX_BYTE
from ._parameters import RAW_VALUE_MAX, RAW_VALUE_MIN, normalize_code, parameter_info
from ._terminals import ASSIGNED_INPUT_BITS, InputTerminal

__all__ = [
    "MAX_FREQUENCY_HZ",
    "Request",
    "can_store",
    "encode_request",
    "initialize",
    "node_wire",
    "read_monitor",
    "read_parameter",
    "read_status",
    "read_trip_history",
    "recalculate",
    "run",
    "set_frequency",
    "set_terminals",
    "store",
    "validate_request",
    "write_parameter",
    "write_parameter_raw",
]

#: The highest frequency command 01's six digits can carry (999999 / 100).
#: A real SJ300 refuses anything above its maximum frequency A004 (<= 400 Hz).
MAX_FREQUENCY_HZ: Final = 9999.99

_NODE_WIRE: Final = {n: b"%02d" % n for n in range(MIN_NODE, MAX_NODE + 1)} | {BROADCAST: b"FF"}
_SIX_DIGITS = re.compile(rb"[0-9]{6}")
_SIXTEEN_HEX = re.compile(rb"[0-9A-Fa-f]{16}")
_EIGHT_DIGITS = re.compile(rb"[0-9]{8}")


def node_wire(node: int) -> bytes:
    """Return the two ASCII characters of *node* (``b"01"``..``b"32"``, ``b"FF"``).

    Raises:
        LocalProtocolError: *node* is not 1..32 or :data:`BROADCAST`.
    """
    if isinstance(node, bool) or not isinstance(node, int):
        raise LocalProtocolError(f"node must be an int 1..32 or BROADCAST, got {node!r}")
    try:
        return _NODE_WIRE[node]
    except KeyError:
        raise LocalProtocolError(f"node must be 1..32 or BROADCAST (0xFF), got {node!r}") from None


def _check_data(command: Command, data: bytes) -> bytes:
    """Check *data* against *command*'s data shape; return it in the form to send."""
    shape = command.spec.request
    if shape is RequestData.NONE:
        if data:
            raise LocalProtocolError(f"command {command.wire.decode()} takes no data, got {data!r}")
        return data
    if shape is RequestData.RUN_MODE:
        if data not in (b"0", b"1", b"2"):
            raise LocalProtocolError(f"command 00 takes b'0', b'1' or b'2', got {data!r}")
        return data
    if shape is RequestData.FREQUENCY:
        if not _SIX_DIGITS.fullmatch(data):
            raise LocalProtocolError(f"command 01 takes six decimal digits, got {data!r}")
        return data
    if shape is RequestData.TERMINALS:
        if not _SIXTEEN_HEX.fullmatch(data):
            raise LocalProtocolError(f"command 02 takes sixteen hex digits, got {data!r}")
        stray = int(data, 16) & ~ASSIGNED_INPUT_BITS
        if stray:
            raise LocalProtocolError(f"command 02 sets unassigned terminal bits {stray:#x}")
        return data.upper()
    if shape is RequestData.PARAMETER_CODE:
        return _code_bytes(data)
    # PARAMETER_VALUE: code + eight digits
    if len(data) != 12 or not _EIGHT_DIGITS.fullmatch(data, 4):
        raise LocalProtocolError(
            f"command 07 takes a parameter code and eight decimal digits, got {data!r}"
        )
    return _code_bytes(data[:4]) + data[4:]


def _code_bytes(code: bytes) -> bytes:
    return normalize_code(code).encode("ascii")


def validate_request(node: int, command: Command | int, data: bytes = b"") -> tuple[bytes, bytes]:
    """Check a request; return ``(node_chars, data_to_send)``.

    Raises:
        LocalProtocolError: unknown command, node out of range, broadcast of a
            command that may not be broadcast, or data of the wrong shape.
    """
    if isinstance(command, bool) or not isinstance(command, int):
        raise LocalProtocolError(f"command must be a Command or its number, got {command!r}")
    try:
        command = Command(command)
    except ValueError:
        raise LocalProtocolError(f"unknown command {command!r}") from None
    if not isinstance(data, bytes | bytearray):
        raise LocalProtocolError(f"data must be bytes, got {type(data).__name__}")
    node_chars = node_wire(node)
    if node == BROADCAST and not command.spec.broadcast:
        raise LocalProtocolError(f"command {command.wire.decode()} may not be broadcast")
    return node_chars, _check_data(command, bytes(data))


@dataclass(frozen=True, slots=True)
class Request:
    """A validated request: where it goes, what it asks, and its frame.

    Build one with :meth:`build` or a typed builder; the constructor does not
    validate.
    """

    #: Node address 1..32, or :data:`BROADCAST`.
    node: int
    #: The command.
    command: Command
    #: The data field as sent.
    data: bytes
    #: The whole frame, STX to CR.
    frame: bytes

    @classmethod
    def build(cls, node: int, command: Command | int, data: bytes = b"") -> Request:
        """Validate and encode a request.

        Raises:
            LocalProtocolError: the protocol does not allow this request.
        """
        node_chars, data = validate_request(node, command, data)
        command = Command(command)
        body = node_chars + command.wire + data
        return cls(node, command, data, STX_BYTE + body + bcc(body) + CR_BYTE)

    @property
    def is_broadcast(self) -> bool:
        """True when the request goes to every drive (and gets no reply)."""
        return self.node == BROADCAST

    @property
    def expects_reply(self) -> bool:
        """True unless broadcast: every SJ300 command to one node is answered."""
        return self.node != BROADCAST

    @property
    def label(self) -> str:
        """``"command 04"``: a short name for messages."""
        return f"command {self.command.wire.decode()}"


def encode_request(node: int, command: Command | int, data: bytes = b"") -> bytes:
    """Return the whole request frame, STX to CR.

    Args:
        node: 1..32, or :data:`BROADCAST`.
        command: a :class:`Command` or its number.
        data: the data field, e.g. ``b"1"`` for command 00 forward.

    Raises:
        LocalProtocolError: the protocol does not allow this request (nothing is produced).

    >>> encode_request(1, Command.RUN, b"1")
    b'\\x020100130\\r'
    """
    return Request.build(node, command, data).frame


# -- typed builders ---------------------------------------------------------

#: Requests without a data field, by (node, command): at most 33 x 12 of them.
_WITHOUT_DATA: dict[tuple[int, Command], Request] = {}


def _without_data(node: int, command: Command) -> Request:
    """The request for a command without data: built and validated once, then shared.

    A poll asks the same few questions of the same drives over and over;
    building and checking the same frame each time is wasted work. Sharing
    is safe: a Request is frozen. Only a plain int is looked up (``True``
    hashes like 1 and must still be refused by :meth:`Request.build`), and
    only a request that was built is stored.
    """
    if type(node) is not int:
        return Request.build(node, command)  # refused, or an int subclass: not shared
    key = (node, command)
    request = _WITHOUT_DATA.get(key)
    if request is None:
        request = _WITHOUT_DATA[key] = Request.build(node, command)
    return request


def run(node: int, direction: Direction | int) -> Request:
    """Command 00: run forward, run reverse or stop."""
    try:
        direction = Direction(direction)
    except ValueError:
        raise LocalProtocolError(f"direction must be a Direction, got {direction!r}") from None
    if not direction.known:
        raise LocalProtocolError(f"direction must be STOP, FORWARD or REVERSE, got {direction!r}")
    return Request.build(node, Command.RUN, b"%d" % direction)


def set_frequency(node: int, hz: float, *, max_hz: float = MAX_FREQUENCY_HZ) -> Request:
    """Command 01: set the output frequency in Hz (0.01 Hz resolution).

    Args:
        max_hz: refuse anything above this (e.g. the drive's A004); defaults
            to what six digits can carry.

    Raises:
        LocalProtocolError: *hz* is not a finite number in ``0..max_hz`` or
            has more than two decimals.
    """
    if isinstance(hz, bool) or not isinstance(hz, int | float) or hz != hz:
        raise LocalProtocolError(f"frequency must be a number of Hz, got {hz!r}")
    if not 0 <= hz <= min(max_hz, MAX_FREQUENCY_HZ):
        raise LocalProtocolError(
            f"frequency must be within 0..{min(max_hz, MAX_FREQUENCY_HZ):g} Hz, got {hz!r}"
        )
    centi = round(hz * 100)
    if abs(centi - hz * 100) > 1e-6:
        raise LocalProtocolError(f"frequency has a resolution of 0.01 Hz, got {hz!r}")
    return Request.build(node, Command.SET_FREQUENCY, b"%06d" % centi)


def set_terminals(node: int, terminals: InputTerminal | int) -> Request:
    """Command 02: set the intelligent input terminals (every bit not given is cleared)."""
    if isinstance(terminals, bool) or not isinstance(terminals, int) or terminals < 0:
        raise LocalProtocolError(f"terminals must be InputTerminal flags, got {terminals!r}")
    if terminals >= 1 << 64:
        raise LocalProtocolError(f"terminal mask {terminals:#x} is wider than 64 bits")
    return Request.build(node, Command.SET_TERMINALS, b"%016X" % int(terminals))


def read_monitor(node: int) -> Request:
    """Command 03: read the monitor block."""
    return _without_data(node, Command.READ_MONITOR)


def read_status(node: int) -> Request:
    """Command 04: read status A/B/C."""
    return _without_data(node, Command.READ_STATUS)


def read_trip_history(node: int) -> Request:
    """Command 05: read the trip history."""
    return _without_data(node, Command.READ_TRIP_HISTORY)


def read_parameter(node: int, code: str) -> Request:
    """Command 06: read one parameter (any syntactically valid code)."""
    return Request.build(node, Command.READ_PARAMETER, normalize_code(code).encode())


def write_parameter_raw(node: int, code: str, raw: int) -> Request:
    """Command 07: write the integer *raw* (0..99999999) to a parameter, unscaled."""
    if isinstance(raw, bool) or not isinstance(raw, int):
        raise LocalProtocolError(f"raw parameter value must be an int, got {raw!r}")
    if not RAW_VALUE_MIN <= raw <= RAW_VALUE_MAX:
        raise LocalProtocolError(
            f"raw parameter value must be within {RAW_VALUE_MIN}..{RAW_VALUE_MAX}, got {raw}"
        )
    return Request.build(
        node, Command.WRITE_PARAMETER, normalize_code(code).encode() + b"%08d" % raw
    )


def write_parameter(node: int, code: str, value: float) -> Request:
    """Command 07: write an engineering value, scaled by the parameter catalogue.

    Raises:
        LocalProtocolError: bad code, value out of the parameter's range or
            finer than its resolution.
    """
    if isinstance(value, bool) or not isinstance(value, int | float) or value != value:
        raise LocalProtocolError(f"parameter value must be a number, got {value!r}")
    return write_parameter_raw(node, code, parameter_info(code).to_raw(value))


def initialize(node: int) -> Request:
    """Command 08: initialize to factory defaults (needs B084 / B085 written first)."""
    return _without_data(node, Command.INITIALIZE)


def can_store(node: int) -> Request:
    """Command 09: ask whether settings may be stored to EEPROM."""
    return _without_data(node, Command.CAN_STORE)


def store(node: int) -> Request:
    """Command 0A: store settings to EEPROM."""
    return _without_data(node, Command.STORE)


def recalculate(node: int) -> Request:
    """Command 0B: recalculate the internal motor constants."""
    return _without_data(node, Command.RECALCULATE)
