"""Frames written out from the protocol reference, independent of the library's codec.

The BCC here is the reference's rule done by hand: XOR of every byte between
STX and the BCC, as two upper-case hex characters. Nothing in this module
calls the library's encoders, so a test comparing against these bytes checks
the simulator against the reference, not against itself.
"""

from __future__ import annotations

from sj300_async.simulator.sj300 import SimulatedBus

STX = b"\x02"
ACK = b"\x06"
NAK = b"\x15"
CR = b"\r"


def xor_bcc(body: bytes) -> bytes:
    """The reference's BCC of *body*."""
    check = 0
    for byte in body:
        check ^= byte
    return b"%02X" % check


def frame(body: bytes) -> bytes:
    """STX body BCC CR."""
    return STX + body + xor_bcc(body) + CR


def request(node: bytes, command: bytes, data: bytes = b"") -> bytes:
    """A request frame: node and command as their two ASCII characters."""
    return frame(node + command + data)


def ack(node: bytes) -> bytes:
    """Positive reply without data."""
    return frame(node + ACK)


def ack_data(node: bytes, data: bytes) -> bytes:
    """Positive reply with data (06, 09)."""
    return frame(node + ACK + data)


def nak(node: bytes, code: bytes) -> bytes:
    """Negative reply with a two-character error code."""
    return frame(node + NAK + code)


def data_reply(node: bytes, data: bytes) -> bytes:
    """Data reply without ACK (03, 04, 05)."""
    return frame(node + data)


def exchange(bus: SimulatedBus, raw: bytes, now: float = 0.0) -> list[bytes]:
    """Feed *raw* to the bus at *now*; return the bytes of every reply, in order."""
    return [t.data for t in bus.receive(raw, now)]


def fields(data: bytes) -> list[bytes]:
    """Split a data block into its 8-character fields."""
    assert len(data) % 8 == 0, data
    return [data[i : i + 8] for i in range(0, len(data), 8)]


def reply_data(reply: bytes, header: int = 3) -> bytes:
    """The data of a reply frame: between the header (STX + node [+ ACK]) and BCC + CR.

    Also checks the frame's BCC by the reference rule.
    """
    assert reply[:1] == STX, reply
    assert reply[-1:] == CR, reply
    assert xor_bcc(reply[1:-3]) == reply[-3:-1], reply
    return reply[header:-3]
