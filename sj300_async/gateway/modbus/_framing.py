"""Modbus TCP, sans-IO: the MBAP framer, the request decoder and the answer encoders.

No I/O and no asyncio (tests/gateway/test_gateway_modbus_framing.py proves
it): the server (:mod:`._server`) feeds what a connection received to a
:class:`Framer` and writes the bytes the encoders return. The contract is
h11's: :meth:`Framer.receive_data` only buffers, :meth:`Framer.next_event`
returns one event or :data:`NEED_DATA`.

An ADU is the 7-byte MBAP header (transaction id, protocol id, length,
unit id) and a PDU (function code and data); *length* counts the unit id
and the PDU. The events:

- :class:`ReadRegisters` (functions 3 and 4) and :class:`WriteRegisters`
  (6 and 16): requests the spec's checks passed, for the server to carry out;
- :class:`Refused`: a well-framed request the codec answers itself with an
  exception (:class:`Exc`), in the spec's order of checks (Modbus
  Application Protocol v1.1b3, section 6): the function first (0x01), then
  the quantity and the PDU's shape (0x03), then the address range (0x02);
- :class:`FrameError`: the stream cannot be framed any more; the
  connection must be closed.

Decisions:

- **A broken header closes the connection.** A protocol id other than 0,
  or a length below 2 (no function code) or above 254 (an ADU over the
  spec's 260 bytes) cannot start a frame. Modbus TCP has no frame
  delimiter to resynchronise on: guessing where the next frame starts
  would answer a request that was never sent, so the framer stops
  (:class:`FrameError`, and every later call returns it again) and the
  client reconnects. A stray byte therefore costs one connection, not the
  connection's every later answer.
- **A header is judged as soon as its 7 bytes are in**, so the bytes of an
  incomplete frame are at most 259; what else is buffered is whole frames
  not yet taken. The buffer is capped all the same (``max_buffer``): past
  it, :class:`FrameError` (a client more than that far ahead of its
  answers is not waiting for them).
- **Functions 3, 4, 6 and 16 only.** Everything else is refused with
  0x01, function 23 (read/write multiple registers) included: a write
  inside a read request would be a second door to the drives' commands,
  judged the same but easy to overlook in a SCADA's configuration; one
  write is one function 6 or 16. Coils, discrete inputs, diagnostics (8),
  event counters (11, 12), report server id (17), FIFO (24), device
  identification (43) and file records (20, 21, 22): the gateway has
  none.
- A request whose PDU is not the length its function implies, a quantity
  outside 1..125 (read) or 1..123 (write multiple), or a byte count other
  than twice the quantity: 0x03. A range past register 65535: 0x02.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import Final

__all__ = [
    "MAX_LENGTH",
    "MAX_READ",
    "MAX_WRITE",
    "NEED_DATA",
    "Exc",
    "FrameError",
    "Framer",
    "ReadRegisters",
    "Refused",
    "WriteRegisters",
    "encode_exception",
    "encode_registers",
    "encode_written",
    "excerpt",
]


class Exc(enum.IntEnum):
    """The Modbus exception codes the gateway answers with."""

    ILLEGAL_FUNCTION = 0x01  #: no such function here; not allowed: read-only, no lease
    ILLEGAL_ADDRESS = 0x02  #: no such register for this unit
    ILLEGAL_VALUE = 0x03  #: a bad quantity or PDU shape, a value the drive must not get
    DEVICE_FAILURE = 0x04  #: the drive refused (NAK) or read back something else
    DEVICE_BUSY = 0x06  #: another client holds the control lease
    PATH_UNAVAILABLE = 0x0A  #: no drive behind this unit id
    TARGET_FAILED = 0x0B  #: stale or missing data, or the drive did not answer


class _NeedData(enum.Enum):
    NEED_DATA = "NEED_DATA"


#: What :meth:`Framer.next_event` returns when no whole frame is buffered.
NEED_DATA: Final = _NeedData.NEED_DATA

#: The largest length field: unit id + 253 bytes of PDU (an ADU of 260 bytes).
MAX_LENGTH: Final = 254
#: The smallest: unit id + function code.
MIN_LENGTH: Final = 2
#: Registers one read (3, 4) and one write (16) may cover.
MAX_READ: Final = 125
MAX_WRITE: Final = 123
#: Bytes a connection may have buffered, frames not yet taken included.
DEFAULT_MAX_BUFFER: Final = 64 * 1024
#: Bytes of a bad frame shown in a log line.
EXCERPT_BYTES: Final = 32

_HEADER: Final = struct.Struct(">HHHB")
_HEADER_SIZE: Final = 7
_READ: Final = struct.Struct(">BHH")  # function, address, count (also 6: address, value)
_WRITE_MULTIPLE: Final = struct.Struct(">BHHB")  # function, address, count, byte count
_EXCEPTION: Final = struct.Struct(">HHHBBB")
_WRITTEN: Final = struct.Struct(">HHHBBHH")


@dataclass(frozen=True, slots=True)
class ReadRegisters:
    """Function 3 or 4: *count* registers from *address*."""

    transaction_id: int
    unit_id: int
    function: int
    address: int
    count: int


@dataclass(frozen=True, slots=True)
class WriteRegisters:
    """Function 6 (one register) or 16 (several): *values* from *address*."""

    transaction_id: int
    unit_id: int
    function: int
    address: int
    values: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class Refused:
    """A well-framed request the codec answers with exception *code* (*reason* says why)."""

    transaction_id: int
    unit_id: int
    function: int
    code: Exc
    reason: str


@dataclass(frozen=True, slots=True)
class FrameError:
    """The stream cannot be framed any more (*reason*).

    *data*: the bytes at fault: the 7-byte header that broke, or the first
    :data:`EXCERPT_BYTES` of an overflowing buffer.
    """

    reason: str
    data: bytes


Event = ReadRegisters | WriteRegisters | Refused | FrameError


class Framer:
    """One connection's receive side (see the module docstring)."""

    __slots__ = ("_buffer", "_error", "_max_buffer")

    def __init__(self, max_buffer: int = DEFAULT_MAX_BUFFER) -> None:
        self._buffer = bytearray()
        self._max_buffer = max_buffer
        self._error: FrameError | None = None

    @property
    def buffered(self) -> int:
        """Bytes received and not yet taken as events."""
        return len(self._buffer)

    def receive_data(self, data: bytes) -> None:
        """Buffer *data*; nothing is parsed until :meth:`next_event`."""
        self._buffer += data

    def next_event(self) -> Event | _NeedData:
        """The next request (or why there is none), or :data:`NEED_DATA`."""
        if self._error is not None:
            return self._error
        buffer = self._buffer
        if len(buffer) > self._max_buffer:
            return self._fail(f"more than {self._max_buffer} bytes waiting", bytes(buffer))
        if len(buffer) < _HEADER_SIZE:
            return NEED_DATA
        tid, protocol, length, unit = _HEADER.unpack_from(buffer)
        if protocol != 0:
            return self._fail(f"protocol id {protocol}, not 0", bytes(buffer[:_HEADER_SIZE]))
        if not MIN_LENGTH <= length <= MAX_LENGTH:
            reason = f"length {length} outside {MIN_LENGTH}..{MAX_LENGTH}"
            return self._fail(reason, bytes(buffer[:_HEADER_SIZE]))
        end = _HEADER_SIZE - 1 + length
        if len(buffer) < end:
            return NEED_DATA
        pdu = bytes(buffer[_HEADER_SIZE:end])
        del buffer[:end]
        return decode_pdu(tid, unit, pdu)

    def _fail(self, reason: str, data: bytes) -> FrameError:
        self._error = FrameError(reason, data[:EXCERPT_BYTES])
        self._buffer.clear()
        return self._error


def decode_pdu(tid: int, unit: int, pdu: bytes) -> Event:
    """The request in *pdu* (at least its function code), after the spec's checks."""
    function = pdu[0]
    if function in (3, 4):
        return _decode_read(tid, unit, pdu)
    if function == 6:
        if len(pdu) != _READ.size:
            return Refused(tid, unit, function, Exc.ILLEGAL_VALUE, f"{len(pdu)}-byte PDU, not 5")
        _, address, value = _READ.unpack(pdu)
        return WriteRegisters(tid, unit, function, address, (value,))
    if function == 16:
        return _decode_write_multiple(tid, unit, pdu)
    return Refused(tid, unit, function, Exc.ILLEGAL_FUNCTION, f"function {function} not served")


def _decode_read(tid: int, unit: int, pdu: bytes) -> Event:
    function = pdu[0]
    if len(pdu) != _READ.size:
        return Refused(tid, unit, function, Exc.ILLEGAL_VALUE, f"{len(pdu)}-byte PDU, not 5")
    _, address, count = _READ.unpack(pdu)
    if not 1 <= count <= MAX_READ:
        return Refused(tid, unit, function, Exc.ILLEGAL_VALUE, f"quantity {count}")
    if address + count > 0x10000:
        return Refused(tid, unit, function, Exc.ILLEGAL_ADDRESS, f"{address}+{count} past 65535")
    return ReadRegisters(tid, unit, function, address, count)


def _decode_write_multiple(tid: int, unit: int, pdu: bytes) -> Event:
    if len(pdu) < _WRITE_MULTIPLE.size:
        return Refused(tid, unit, 16, Exc.ILLEGAL_VALUE, f"{len(pdu)}-byte PDU")
    _, address, count, byte_count = _WRITE_MULTIPLE.unpack_from(pdu)
    if not 1 <= count <= MAX_WRITE or byte_count != 2 * count:
        return Refused(
            tid, unit, 16, Exc.ILLEGAL_VALUE, f"quantity {count}, byte count {byte_count}"
        )
    if len(pdu) != _WRITE_MULTIPLE.size + byte_count:
        return Refused(tid, unit, 16, Exc.ILLEGAL_VALUE, f"{len(pdu)}-byte PDU for {count}")
    if address + count > 0x10000:
        return Refused(tid, unit, 16, Exc.ILLEGAL_ADDRESS, f"{address}+{count} past 65535")
    values = struct.unpack_from(f">{count}H", pdu, _WRITE_MULTIPLE.size)
    return WriteRegisters(tid, unit, 16, address, values)


# -- the answers ----------------------------------------------------------------------


def encode_registers(tid: int, unit: int, function: int, values: list[int]) -> bytes:
    """The answer to a read: *values* (each 0..65535)."""
    n = len(values)
    return struct.pack(f">HHHBBB{n}H", tid, 0, 3 + 2 * n, unit, function, 2 * n, *values)


def encode_written(tid: int, unit: int, function: int, address: int, word: int) -> bytes:
    """The answer to a write: function 6 echoes (address, value), 16 (address, quantity)."""
    return _WRITTEN.pack(tid, 0, 6, unit, function, address, word)


def encode_exception(tid: int, unit: int, function: int, code: int) -> bytes:
    """An exception answer: the function with its high bit set, and *code*."""
    return _EXCEPTION.pack(tid, 0, 3, unit, (function | 0x80) & 0xFF, code)


def excerpt(data: bytes, limit: int = EXCERPT_BYTES) -> str:
    """*data* as hex for a log line, at most *limit* bytes of it (the rest counted)."""
    shown = data[:limit].hex(" ")
    return shown if len(data) <= limit else f"{shown} ... ({len(data)} bytes)"
