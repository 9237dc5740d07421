"""Encoding replies and their payloads: the drive's side of the codec.

The simulator answers with these, and the tests use them to build the
streams the parser must read back. Each encoder is the exact inverse of the
decoder of the same name in :mod:`._payloads`.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..wire import LocalProtocolError
from ._bcc import bcc
from ._constants import ACK_BYTE, CR_BYTE, MAX_NODE, MIN_NODE, NAK_BYTE, STX_BYTE
from ._events import AckDataReply, AckReply, DataReply, NakReply, Reply
from ._payloads import InverterStatus, MonitorData, TripHistory

__all__ = [
    "encode_decimal_field",
    "encode_monitor",
    "encode_reply",
    "encode_status",
    "encode_trip_history",
    "frame_body",
]

# What an 8-character decimal field can carry.
_FIELD_MIN = -9_999_999
_FIELD_MAX = 99_999_999


def frame_body(body: bytes) -> bytes:
    """Wrap *body* (node .. last data byte) as ``STX body BCC CR``."""
    return STX_BYTE + body + bcc(body) + CR_BYTE


def encode_reply(reply: Reply) -> bytes:
    """Return the whole reply frame for a reply event.

    Raises:
        LocalProtocolError: the node is not 1..32 (a broadcast gets no reply).
    """
    if not MIN_NODE <= reply.node <= MAX_NODE:
        raise LocalProtocolError(f"a reply comes from node 1..32, got {reply.node!r}")
    node = b"%02d" % reply.node
    if isinstance(reply, AckReply):
        return frame_body(node + ACK_BYTE)
    if isinstance(reply, AckDataReply):
        return frame_body(node + ACK_BYTE + reply.data)
    if isinstance(reply, NakReply):
        return frame_body(node + NAK_BYTE + b"%02d" % reply.code)
    if isinstance(reply, DataReply):
        return frame_body(node + reply.data)
    raise TypeError(f"not a reply: {reply!r}")


def encode_decimal_field(value: int) -> bytes:
    """Format an integer as an 8-character decimal field (``-`` and 7 digits when negative).

    Raises:
        LocalProtocolError: the value does not fit in 8 characters.
    """
    if not _FIELD_MIN <= value <= _FIELD_MAX:
        raise LocalProtocolError(f"{value} does not fit in an 8-character field")
    return b"-%07d" % -value if value < 0 else b"%08d" % value


def _fields(values: Sequence[int]) -> bytes:
    """:func:`encode_decimal_field` of every value, joined."""
    if min(values) < _FIELD_MIN or max(values) > _FIELD_MAX:
        return b"".join(encode_decimal_field(v) for v in values)  # raises for the first misfit
    # One format for all of them: "%08d" pads a negative number as "-" and 7 digits,
    # the same characters encode_decimal_field makes.
    return (b"%08d" * len(values)) % tuple(values)


def encode_status(status: InverterStatus) -> bytes:
    """Return the 8 data characters of a command 04 reply."""
    return b"%02d%02d%02d00" % (status.a, status.b, status.c)


def encode_monitor(m: MonitorData) -> bytes:
    """Return the 104 data characters of a command 03 reply."""
    head = _fields(
        (
            round(m.output_frequency_hz * 100),
            round(m.output_current_a * 10),
            int(m.direction),
            round(m.pid_feedback_percent * 100),
        )
    )
    terminals = b"%08X%08X" % (int(m.input_terminals), int(m.output_terminals))
    tail = _fields(
        (
            round(m.frequency_conversion * 100),
            m.output_torque_percent,
            round(m.output_voltage_v * 10),
            round(m.power_kw * 10),
            0,
            m.run_time_h,
            m.power_on_time_h,
        )
    )
    return head + terminals + tail


def encode_trip_history(history: TripHistory) -> bytes:
    """Return the 440 data characters of a command 05 reply.

    Raises:
        LocalProtocolError: the history does not hold exactly six records.
    """
    if len(history.records) != 6:
        raise LocalProtocolError(f"a trip history holds 6 records, got {len(history.records)}")
    values = [history.total_count]
    for r in history.records:
        values += (
            r.trip_factor,
            int(r.status_a),
            int(r.status_b),
            int(r.status_c),
            round(r.output_frequency_hz * 10),
            r.run_time_h,
            round(r.output_current_a * 10),
            round(r.output_voltage_v * 10),
            r.power_on_time_h,
        )
    return _fields(values)
