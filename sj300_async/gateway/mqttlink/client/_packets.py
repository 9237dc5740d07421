"""MQTT 3.1.1 packets, sans-IO: the encoders a client needs and a parser of what a broker sends.

Only the client's side of MQTT 3.1.1 (OASIS standard, 2014) is here: the
packets a client sends (CONNECT, PUBLISH, PUBACK, SUBSCRIBE, UNSUBSCRIBE,
PINGREQ, DISCONNECT) are encoded, the ones a broker sends (CONNACK,
PUBLISH, PUBACK, SUBACK, UNSUBACK, PINGRESP) are parsed. QoS 2 is not
spoken: the client never publishes or subscribes at QoS 2, so a broker has
no reason to send one of its packets, and one that does breaks the protocol
(:class:`MalformedPacket`).

The parser takes byte chunks as they come and returns whole packets. A
PUBLISH whose payload is longer than its ``max_publish_bytes`` is not held
in memory: its header and the payload's first bytes are returned as
:class:`Oversized` (so the client can acknowledge it and report it), and
the rest is skipped as it arrives. (A topic, at most 65,535 bytes, is always read.)
Anything else a broker sends that breaks the protocol raises
:class:`MalformedPacket`; the connection is then beyond repair.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Final

__all__ = [
    "CONNACK_REASONS",
    "DISCONNECT",
    "MAX_REMAINING",
    "PINGREQ",
    "ConnAck",
    "MalformedPacket",
    "Oversized",
    "Packet",
    "PacketParser",
    "PingResp",
    "PubAck",
    "Publish",
    "SubAck",
    "UnsubAck",
    "encode_connect",
    "encode_puback",
    "encode_publish",
    "encode_subscribe",
    "encode_unsubscribe",
]

#: The largest remaining length a fixed header can carry (four length bytes).
MAX_REMAINING: Final = 268_435_455

PINGREQ: Final = b"\xc0\x00"
DISCONNECT: Final = b"\xe0\x00"

#: CONNACK's return codes (section 3.2.2.3), as a sentence each.
CONNACK_REASONS: Final = {
    1: "the broker does not speak MQTT 3.1.1",
    2: "the broker rejected the client identifier",
    3: "the broker is unavailable",
    4: "the broker rejected the user name or password",
    5: "the broker did not authorize the connection",
}

_U16 = struct.Struct("!H")

#: The packets a broker sends but PUBLISH, and the most bytes each carries after its
#: fixed header (a SUBACK: one code per filter; we subscribe a few at a time).
_MOST: Final = {2: 2, 4: 2, 9: 2 + 1024, 11: 2, 13: 0}
_NAMES: Final = {1: "CONNECT", 2: "CONNACK", 3: "PUBLISH", 4: "PUBACK", 5: "PUBREC",
                 6: "PUBREL", 7: "PUBCOMP", 8: "SUBSCRIBE", 9: "SUBACK", 10: "UNSUBSCRIBE",
                 11: "UNSUBACK", 12: "PINGREQ", 13: "PINGRESP", 14: "DISCONNECT"}  # fmt: skip


class MalformedPacket(Exception):
    """The broker sent bytes that break MQTT 3.1.1; the connection cannot go on."""


@dataclass(frozen=True, slots=True)
class ConnAck:
    session_present: bool
    return_code: int


@dataclass(frozen=True, slots=True)
class Publish:
    topic: str
    payload: bytes
    qos: int
    retain: bool
    #: The packet identifier of a QoS 1 message (to acknowledge), else None.
    packet_id: int | None
    dup: bool = False


@dataclass(frozen=True, slots=True)
class Oversized:
    """A PUBLISH longer than the parser's limit: its header; its payload was skipped."""

    topic: str
    qos: int
    packet_id: int | None
    retain: bool
    #: The payload's length.
    length: int
    #: The payload's first bytes (at most the parser's ``head_bytes``), for an excerpt.
    head: bytes = b""


@dataclass(frozen=True, slots=True)
class PubAck:
    packet_id: int


@dataclass(frozen=True, slots=True)
class SubAck:
    packet_id: int
    #: One per topic filter: the QoS granted, or 0x80 for a refusal.
    return_codes: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class UnsubAck:
    packet_id: int


@dataclass(frozen=True, slots=True)
class PingResp:
    pass


Packet = ConnAck | Publish | Oversized | PubAck | SubAck | UnsubAck | PingResp


# -- encoding ---------------------------------------------------------------------------


def _length(n: int) -> bytes:
    """The remaining length, as the fixed header's variable-length integer."""
    if n < 128:
        return bytes((n,))
    if n > MAX_REMAINING:
        raise ValueError(f"an MQTT packet carries at most {MAX_REMAINING} bytes, not {n}")
    out = bytearray()
    while True:
        n, digit = divmod(n, 128)
        if n:
            out.append(digit | 0x80)
        else:
            out.append(digit)
            return bytes(out)


def _string(text: str | bytes) -> bytes:
    data = text.encode() if isinstance(text, str) else text
    if len(data) > 0xFFFF:
        raise ValueError(f"an MQTT string is at most 65535 bytes, not {len(data)}")
    return _U16.pack(len(data)) + data


def encode_connect(
    client_id: str,
    *,
    keepalive_s: int,
    clean_session: bool = True,
    username: str | None = None,
    password: str | None = None,
    will: tuple[str, bytes, int, bool] | None = None,
) -> bytes:
    """CONNECT; *will* is (topic, payload, qos, retain)."""
    if not 0 <= keepalive_s <= 0xFFFF:
        raise ValueError(f"keepalive must be 0..65535 s, not {keepalive_s}")
    flags = 0x02 if clean_session else 0
    payload = [_string(client_id)]
    if will is not None:
        topic, message, qos, retain = will
        flags |= 0x04 | (qos << 3) | (0x20 if retain else 0)
        payload += [_string(topic), _string(message)]
    if username is not None:
        flags |= 0x80
        payload.append(_string(username))
        if password is not None:
            flags |= 0x40
            payload.append(_string(password))
    body = b"\x00\x04MQTT\x04" + bytes((flags,)) + _U16.pack(keepalive_s) + b"".join(payload)
    return b"\x10" + _length(len(body)) + body


def encode_publish(
    topic: bytes, payload: bytes, *, qos: int = 0, retain: bool = False, packet_id: int = 0
) -> bytes:
    """PUBLISH; *topic* already UTF-8 (a caller that publishes often encodes it once)."""
    head = 0x30 | (qos << 1) | (1 if retain else 0)
    if qos:
        variable = _U16.pack(len(topic)) + topic + _U16.pack(packet_id)
    else:
        variable = _U16.pack(len(topic)) + topic
    size = len(variable) + len(payload)
    if size < 128:  # the usual small message: one length byte, no call
        return bytes((head, size)) + variable + payload
    return bytes((head,)) + _length(size) + variable + payload


def encode_puback(packet_id: int) -> bytes:
    return b"\x40\x02" + _U16.pack(packet_id)


def encode_subscribe(packet_id: int, filters: list[tuple[str, int]]) -> bytes:
    body = _U16.pack(packet_id) + b"".join(_string(f) + bytes((qos,)) for f, qos in filters)
    return b"\x82" + _length(len(body)) + body


def encode_unsubscribe(packet_id: int, filters: list[str]) -> bytes:
    body = _U16.pack(packet_id) + b"".join(_string(f) for f in filters)
    return b"\xa2" + _length(len(body)) + body


# -- parsing ----------------------------------------------------------------------------


class PacketParser:
    """What a broker sends, chunk by chunk, as :data:`Packet` values."""

    def __init__(self, *, max_publish_bytes: int = 1 << 20, head_bytes: int = 256) -> None:
        self._buffer = bytearray()
        self._skip = 0  # bytes of an oversized PUBLISH still to come
        self.max_publish_bytes = max_publish_bytes
        self.head_bytes = head_bytes

    def feed(self, data: bytes | memoryview) -> list[Packet]:
        """The packets completed by *data* (raises :class:`MalformedPacket`).

        *data* may be a view of the caller's reused read buffer: nothing refers to
        it once this returns (what is kept, and every packet, is a copy).
        """
        if self._skip:
            taken = min(self._skip, len(data))
            self._skip -= taken
            data = data[taken:]
        buffer = self._buffer
        buffer += data
        packets: list[Packet] = []
        start = 0
        end = len(buffer)
        while end - start >= 2:
            first = buffer[start]
            # The remaining length: one to four bytes, seven bits each.
            size = shift = 0
            at = start + 1
            complete = False
            while at < end:
                byte = buffer[at]
                at += 1
                size |= (byte & 0x7F) << shift
                if not byte & 0x80:
                    complete = True
                    break
                shift += 7
                if shift > 21:
                    raise MalformedPacket("a remaining length of more than four bytes")
            if not complete:
                break
            kind = first >> 4
            if kind != 3 and size > _MOST.get(kind, -1):
                # Judged before the body comes: a broker must not make us hold a
                # 256 MB "PUBACK" (a type it never sends fails here at once too).
                if kind not in _MOST:
                    raise MalformedPacket(f"packet type {_NAMES.get(kind, kind)} from a broker")
                raise MalformedPacket(f"{_NAMES[kind]} of {size} bytes")
            if first >> 4 == 3 and size > self.max_publish_bytes:
                # Perhaps a payload past the limit: read the header (topic, packet id),
                # and skip the payload as it comes if it is.
                if end - at < 2:
                    break
                topic_len = _U16.unpack_from(buffer, at)[0]
                header = 2 + topic_len + (2 if (first >> 1) & 3 else 0)
                length = size - header
                if length > self.max_publish_bytes:
                    need = header + min(length, self.head_bytes)
                    if end - at < need:
                        break
                    packet = _publish(first, bytes(buffer[at : at + header]), header=True)
                    head = bytes(buffer[at + header : at + need])
                    packets.append(
                        Oversized(
                            packet.topic, packet.qos, packet.packet_id, packet.retain, length, head
                        )
                    )
                    if end - at >= size:
                        start = at + size
                        continue
                    self._skip = size - (end - at)
                    start = end
                    break
            if end - at < size:
                break
            packets.append(_parse(first, bytes(buffer[at : at + size])))
            start = at + size
        if start:
            del buffer[:start]
        return packets


def _parse(first: int, body: bytes) -> Packet:
    kind = first >> 4
    flags = first & 0x0F
    if kind == 3:
        return _publish(first, body)
    if kind in (4, 11) and flags == 0 and len(body) == 2:  # PUBACK, UNSUBACK
        packet_id = _U16.unpack_from(body)[0]
        return PubAck(packet_id) if kind == 4 else UnsubAck(packet_id)
    if kind == 9 and flags == 0 and len(body) >= 3:  # SUBACK
        codes = body[2:]
        if any(code not in (0, 1, 2, 0x80) for code in codes):
            raise MalformedPacket(f"SUBACK with return codes {codes.hex()}")
        return SubAck(_U16.unpack_from(body)[0], tuple(codes))
    if kind == 13 and flags == 0 and not body:
        return PingResp()
    if kind == 2 and flags == 0 and len(body) == 2:  # CONNACK
        if body[0] & 0xFE:
            raise MalformedPacket(f"CONNACK with flags {body[0]:#04x}")
        return ConnAck(bool(body[0] & 1), body[1])
    raise MalformedPacket(f"{_NAMES[kind]} with flags {flags:#x} and {len(body)} bytes")


def _publish(first: int, body: bytes, *, header: bool = False) -> Publish:
    qos = (first >> 1) & 3
    if qos == 3:
        raise MalformedPacket("PUBLISH with QoS 3")
    if qos == 2:
        raise MalformedPacket("PUBLISH with QoS 2 (never subscribed at QoS 2)")
    if len(body) < 2:
        raise MalformedPacket("PUBLISH without a topic")
    topic_len = _U16.unpack_from(body)[0]
    at = 2 + topic_len
    if len(body) < at + (2 if qos else 0):
        raise MalformedPacket("PUBLISH shorter than its topic")
    try:
        topic = str(body[2:at], "utf-8")
    except UnicodeDecodeError:
        raise MalformedPacket("PUBLISH with a topic that is not UTF-8") from None
    packet_id = None
    if qos:
        packet_id = _U16.unpack_from(body, at)[0]
        at += 2
        if not packet_id:
            raise MalformedPacket("PUBLISH at QoS 1 with packet identifier 0")
    payload = b"" if header else body[at:]
    return Publish(topic, payload, qos, bool(first & 1), packet_id, bool(first & 8))
