"""FR-700 frames written out from the protocol reference, independent of the library's codec.

The sum check here is the reference's rule done by hand: the low byte of
the arithmetic sum of the characters from the station number through the
last data character, as two upper-case hex characters. Nothing in this
module calls the library's encoders, so a test comparing against these
bytes checks the library against the reference, not against itself.
"""

from __future__ import annotations

ENQ = b"\x05"
STX = b"\x02"
ETX = b"\x03"
ACK = b"\x06"
NAK = b"\x15"
CR = b"\r"
LF = b"\n"


def ref_sum(chars: bytes) -> bytes:
    """The reference's sum check of *chars*."""
    total = 0
    for byte in chars:
        total += byte
    return b"%02X" % (total % 256)


def request(
    station: int, code: int, data: bytes = b"", *, wait: bytes = b"0", term: bytes = CR
) -> bytes:
    """Formats A, A1, A2, B: ENQ station instruction [wait] data sum [term]."""
    body = b"%02X%02X" % (station, code) + wait + data
    return ENQ + body + ref_sum(body) + term


def data_reply(station: int, data: bytes, term: bytes = CR) -> bytes:
    """Formats E, E1, E2, E3, C1: STX station data ETX sum [term]."""
    body = b"%02X" % station + data
    return STX + body + ETX + ref_sum(body) + term


def ack(station: int, term: bytes = CR) -> bytes:
    """Format C (either direction): ACK station [term]."""
    return ACK + b"%02X" % station + term


def nak(station: int, code: bytes, term: bytes = CR) -> bytes:
    """Format D: NAK station code [term]."""
    return NAK + b"%02X" % station + code + term


def reoutput(station: int, term: bytes = CR) -> bytes:
    """Format F from the host: NAK station [term]."""
    return NAK + b"%02X" % station + term
