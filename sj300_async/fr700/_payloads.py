"""Decoders from FR-700 reply data to typed results (frozen, slotted, units in field names).

Scales (the reference): frequencies x 0.01 Hz, output current x 0.01 A,
output voltage x 0.1 V. :class:`Fr700Monitor` names its fields like the
SJ300's :class:`~sj300_async.MonitorData`, so the poller and the command
line show either drive the same way.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from ..wire import RemoteProtocolError
from ._codes import Fr700NakCode, Fr700StatusBits
from ._requests import Fr700MultiReceive

__all__ = [
    "Fr700Monitor",
    "Fr700MultiReply",
    "Fr700Status",
    "decode_hex",
    "decode_multi_reply",
]

_HEX: Final = re.compile(rb"[0-9A-Fa-f]+")
_MULTI: Final = re.compile(rb"[01][0-3][0-9A-Fa-f]{10}")
# Divisors, not factors: 833 / 10 is 83.3, 833 * 0.1 is not.
_DIVISORS: Final = {
    Fr700MultiReceive.OUTPUT_FREQUENCY: 100,
    Fr700MultiReceive.OUTPUT_CURRENT: 100,
    Fr700MultiReceive.OUTPUT_VOLTAGE: 10,
    Fr700MultiReceive.SPECIAL_MONITOR: 1,
}


def decode_hex(data: bytes) -> int:
    """The value of a data field of hex digits.

    Raises:
        RemoteProtocolError: the field is not hex digits.
    """
    if not _HEX.fullmatch(data):
        raise RemoteProtocolError(f"expected hex digits, got {data!r}")
    return int(data, 16)


@dataclass(frozen=True, slots=True)
class Fr700Status:
    """The status monitor: H7A (8 bits) or H79 (16 bits)."""

    bits: Fr700StatusBits
    #: True when read with H79: bits 8..15 are meaningful.
    extended: bool = False

    @property
    def running(self) -> bool:
        """The inverter outputs (RUN)."""
        return Fr700StatusBits.RUN in self.bits

    @property
    def forward(self) -> bool:
        """Forward rotation."""
        return Fr700StatusBits.FORWARD in self.bits

    @property
    def reverse(self) -> bool:
        """Reverse rotation."""
        return Fr700StatusBits.REVERSE in self.bits

    @property
    def up_to_frequency(self) -> bool:
        """The output has reached the set frequency (SU)."""
        return Fr700StatusBits.SU in self.bits

    @property
    def tripped(self) -> bool:
        """A fault is latched (ABC1, or the H79 fault bit)."""
        return bool(self.bits & (Fr700StatusBits.ABC1 | Fr700StatusBits.FAULT))


@dataclass(frozen=True, slots=True)
class Fr700Monitor:
    """Output frequency (H6F), current (H70) and voltage (H71)."""

    output_frequency_hz: float
    output_current_a: float
    output_voltage_v: float


@dataclass(frozen=True, slots=True)
class Fr700MultiReply:
    """Format C1: what a multi-command (HF0) did and reports.

    The two error fields say how each half of the request fared:
    :attr:`Fr700NakCode.NO_ERROR` (F) when it was carried out, MODE (A) or
    DATA_RANGE (C) when it was refused (other errors come as a NAK instead).
    """

    #: 0: the set frequency went to RAM; 1: to RAM and EEPROM.
    send_type: int
    receive_type: Fr700MultiReceive
    #: How the run command (data1) fared.
    run_error: Fr700NakCode
    #: How the set frequency (data2) fared.
    frequency_error: Fr700NakCode
    #: The extended status monitor (H79 layout).
    status: Fr700Status
    #: data2 as sent (see :attr:`value`).
    raw_value: int

    @property
    def ok(self) -> bool:
        """True when both halves were carried out."""
        return self.run_error is Fr700NakCode.NO_ERROR and (
            self.frequency_error is Fr700NakCode.NO_ERROR
        )

    @property
    def value(self) -> float:
        """data2 scaled by :attr:`receive_type`: Hz, A, V, or the raw special monitor."""
        return self.raw_value / _DIVISORS[self.receive_type]


def decode_multi_reply(data: bytes) -> Fr700MultiReply:
    """Decode the twelve data characters of a C1 reply.

    Raises:
        RemoteProtocolError: not twelve characters of the C1 layout.
    """
    if not _MULTI.fullmatch(data):
        raise RemoteProtocolError(f"malformed multi-command reply: {data!r}")
    return Fr700MultiReply(
        send_type=data[0] - 0x30,
        receive_type=Fr700MultiReceive(data[1] - 0x30),
        run_error=Fr700NakCode(int(data[2:3], 16)),
        frequency_error=Fr700NakCode(int(data[3:4], 16)),
        status=Fr700Status(Fr700StatusBits(int(data[4:8], 16)), extended=True),
        raw_value=int(data[8:12], 16),
    )
