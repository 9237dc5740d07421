"""pcapng, written and read with the standard library (sans-IO: bytes in, bytes out).

What a capture of ours holds (docs/CAPTURE.md has the whole story):

- one Section Header Block, naming us in ``shb_userappl``;
- one Interface Description Block per line: the protocol's user link type
  (147..162: SJ300 147, FR-700 148), ``if_name`` the bus, ``if_description``
  the protocol and line settings (``"sj300 19200 8N1"``, ``"fr700 instant"``),
  ``if_speed`` the baud rate, ``if_tsresol`` microseconds;
- one Enhanced Packet Block per frame as it crossed the line, its direction
  in ``epb_flags`` (inbound: reached the host; outbound: the host wrote it;
  neither: seen on a tap), a wrong check code as the flags' CRC-error bit,
  bytes outside any frame as the symbol-error bit, and every marked packet a
  comment naming its problem.

The reader takes what Wireshark writes as well (either byte order, other
block types skipped, several sections) and refuses anything malformed with
a :class:`CaptureFormatError` that says where.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Final

from ._errors import LocalProtocolError

__all__ = [
    "FLAG_CHECK_ERROR",
    "FLAG_NOISE",
    "CaptureFormatError",
    "CapturedPacket",
    "PacketDirection",
    "PcapngCapture",
    "PcapngInterface",
    "PcapngWriter",
    "read_pcapng",
]

_SHB: Final = 0x0A0D0D0A
_IDB: Final = 0x00000001
_EPB: Final = 0x00000006
_BYTE_ORDER_MAGIC: Final = 0x1A2B3C4D

_OPT_END: Final = 0
_OPT_COMMENT: Final = 1
_SHB_USERAPPL: Final = 4
_IF_NAME: Final = 2
_IF_DESCRIPTION: Final = 3
_IF_SPEED: Final = 8
_IF_TSRESOL: Final = 9
_EPB_FLAGS: Final = 2

#: ``epb_flags`` link-layer error bits: the frame's check code is wrong (CRC error) ...
FLAG_CHECK_ERROR: Final = 1 << 24
#: ... and bytes outside any frame, or a frame cut short (symbol error).
FLAG_NOISE: Final = 1 << 31
_DIRECTION_MASK: Final = 0b11


class PacketDirection(enum.IntEnum):
    """``epb_flags`` bits 0-1."""

    UNKNOWN = 0  #: seen on a tap, direction not known
    INBOUND = 1  #: reached the host (a drive's reply, the local echo)
    OUTBOUND = 2  #: the host wrote it


class CaptureFormatError(LocalProtocolError):
    """A capture file that is not pcapng, or is damaged (the message says where)."""


@dataclass(frozen=True, slots=True)
class PcapngInterface:
    """An Interface Description Block: one line."""

    linktype: int
    name: str = ""
    description: str = ""
    #: The line's speed in bits per second (0: not given, or an instant line).
    speed: int = 0


@dataclass(frozen=True, slots=True)
class CapturedPacket:
    """An Enhanced Packet Block: one frame (or run of noise) as it crossed the line."""

    interface: int
    #: Microseconds since the epoch (UTC).
    timestamp_us: int
    data: bytes
    direction: PacketDirection
    #: The whole ``epb_flags`` word (direction and error bits).
    flags: int = 0
    comment: str = ""

    @property
    def timestamp(self) -> float:
        """Seconds since the epoch."""
        return self.timestamp_us / 1e6


@dataclass(frozen=True, slots=True)
class PcapngCapture:
    """A whole capture: its interfaces and its packets, in file order."""

    interfaces: tuple[PcapngInterface, ...]
    packets: tuple[CapturedPacket, ...]
    application: str = ""


def _option(code: int, value: bytes) -> bytes:
    pad = -len(value) % 4
    return struct.pack("<HH", code, len(value)) + value + b"\0" * pad


def _options(options: list[bytes]) -> bytes:
    return b"".join(options) + struct.pack("<HH", _OPT_END, 0) if options else b""


def _block(block_type: int, body: bytes) -> bytes:
    length = 12 + len(body)
    return struct.pack("<II", block_type, length) + body + struct.pack("<I", length)


class PcapngWriter:
    """Encodes a capture block by block (little-endian); the caller writes the bytes."""

    def __init__(self) -> None:
        self._interfaces = 0

    def section(self, application: str) -> bytes:
        """The Section Header Block that starts the file."""
        body = struct.pack("<IHHq", _BYTE_ORDER_MAGIC, 1, 0, -1)
        body += _options([_option(_SHB_USERAPPL, application.encode())])
        return _block(_SHB, body)

    def interface(self, interface: PcapngInterface) -> tuple[int, bytes]:
        """The interface's number and its Interface Description Block."""
        if not 0 <= interface.linktype <= 0xFFFF:
            raise LocalProtocolError(f"link type must be 0..65535, got {interface.linktype}")
        options = [_option(_IF_TSRESOL, b"\x06")]  # microseconds
        if interface.name:
            options.append(_option(_IF_NAME, interface.name.encode()))
        if interface.description:
            options.append(_option(_IF_DESCRIPTION, interface.description.encode()))
        if interface.speed:
            options.append(_option(_IF_SPEED, struct.pack("<Q", interface.speed)))
        body = struct.pack("<HHI", interface.linktype, 0, 0) + _options(options)
        number = self._interfaces
        self._interfaces += 1
        return number, _block(_IDB, body)

    def packet(self, packet: CapturedPacket) -> bytes:
        """The Enhanced Packet Block of one packet."""
        if not 0 <= packet.interface < self._interfaces:
            raise LocalProtocolError(f"no interface {packet.interface} in this capture")
        data = packet.data
        stamp = packet.timestamp_us
        head = struct.pack(
            "<IIIII", packet.interface, stamp >> 32, stamp & 0xFFFFFFFF, len(data), len(data)
        )
        options = []
        if packet.comment:
            options.append(_option(_OPT_COMMENT, packet.comment.encode()))
        flags = packet.flags | packet.direction
        if flags:
            options.append(_option(_EPB_FLAGS, struct.pack("<I", flags)))
        return _block(_EPB, head + data + b"\0" * (-len(data) % 4) + _options(options))


def _read_options(data: bytes, order: str, where: str) -> Iterator[tuple[int, bytes]]:
    pos = 0
    while pos + 4 <= len(data):
        code, length = struct.unpack_from(order + "HH", data, pos)
        if code == _OPT_END:
            return
        end = pos + 4 + length
        if end > len(data):
            raise CaptureFormatError(f"{where}: option {code} runs past its block")
        yield code, data[pos + 4 : end]
        pos = end + (-length % 4)


def read_pcapng(data: bytes) -> PcapngCapture:
    """Parse a pcapng file's bytes.

    Raises:
        CaptureFormatError: not pcapng, truncated, or damaged; the message
            gives the byte offset.
    """
    if len(data) < 12 or struct.unpack_from("<I", data)[0] != _SHB:
        raise CaptureFormatError("not a pcapng file (no section header block at its start)")
    interfaces: list[PcapngInterface] = []
    resolutions: list[int] = []  # units per second, per interface
    packets: list[CapturedPacket] = []
    application = ""
    order = "<"
    pos = 0
    while pos < len(data):
        where = f"block at byte {pos}"
        if len(data) - pos < 12:
            raise CaptureFormatError(f"{where}: the file ends inside a block header")
        if struct.unpack_from("<I", data, pos)[0] == _SHB:
            magic = data[pos + 8 : pos + 12]
            if magic == struct.pack("<I", _BYTE_ORDER_MAGIC):
                order = "<"
            elif magic == struct.pack(">I", _BYTE_ORDER_MAGIC):
                order = ">"
            else:
                raise CaptureFormatError(f"{where}: bad byte-order magic {magic.hex()}")
            interfaces, resolutions = [], []  # interfaces belong to their section
        block_type, length = struct.unpack_from(order + "II", data, pos)
        if length < 12 or length % 4 or pos + length > len(data):
            raise CaptureFormatError(f"{where}: bad block length {length}")
        if struct.unpack_from(order + "I", data, pos + length - 4)[0] != length:
            raise CaptureFormatError(f"{where}: its two lengths differ")
        body = data[pos + 8 : pos + length - 4]
        if block_type == _SHB:
            if len(body) < 16:
                raise CaptureFormatError(f"{where}: section header too short")
            for code, value in _read_options(body[16:], order, where):
                if code == _SHB_USERAPPL:
                    application = value.decode("utf-8", "replace")
        elif block_type == _IDB:
            interface, resolution = _read_interface(body, order, where)
            interfaces.append(interface)
            resolutions.append(resolution)
        elif block_type == _EPB:
            packets.append(_read_packet(body, order, where, resolutions))
        pos += length
    return PcapngCapture(tuple(interfaces), tuple(packets), application)


def _read_interface(body: bytes, order: str, where: str) -> tuple[PcapngInterface, int]:
    if len(body) < 8:
        raise CaptureFormatError(f"{where}: interface description too short")
    (linktype,) = struct.unpack_from(order + "H", body)
    name = description = ""
    speed = 0
    resolution = 1_000_000
    for code, value in _read_options(body[8:], order, where):
        if code == _IF_NAME:
            name = value.decode("utf-8", "replace")
        elif code == _IF_DESCRIPTION:
            description = value.decode("utf-8", "replace")
        elif code == _IF_SPEED and len(value) == 8:
            (speed,) = struct.unpack(order + "Q", value)
        elif code == _IF_TSRESOL and len(value) == 1:
            exponent = value[0] & 0x7F
            resolution = 2**exponent if value[0] & 0x80 else 10**exponent
    return PcapngInterface(linktype, name, description, speed), resolution


def _read_packet(body: bytes, order: str, where: str, resolutions: list[int]) -> CapturedPacket:
    if len(body) < 20:
        raise CaptureFormatError(f"{where}: packet block too short")
    interface, high, low, captured, _original = struct.unpack_from(order + "IIIII", body)
    if interface >= len(resolutions):
        raise CaptureFormatError(
            f"{where}: packet of interface {interface}, which is not described"
        )
    end = 20 + captured
    if end > len(body):
        raise CaptureFormatError(f"{where}: packet data runs past its block")
    flags = 0
    comment = ""
    for code, value in _read_options(body[end + (-captured % 4) :], order, where):
        if code == _EPB_FLAGS and len(value) == 4:
            (flags,) = struct.unpack(order + "I", value)
        elif code == _OPT_COMMENT:
            comment = value.decode("utf-8", "replace")
    units = (high << 32) | low
    resolution = resolutions[interface]
    stamp = units if resolution == 1_000_000 else units * 1_000_000 // resolution
    return CapturedPacket(
        interface,
        stamp,
        body[20:end],
        PacketDirection(flags & _DIRECTION_MASK)
        if flags & _DIRECTION_MASK != 3
        else PacketDirection.UNKNOWN,
        flags,
        comment,
    )
