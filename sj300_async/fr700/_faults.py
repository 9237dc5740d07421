"""The FR-700 fault history (H74..H77): its fault codes, named, and the history decoded.

The drive keeps its last eight trips, two to a reply: H74's low byte is the
most recent, its high byte the one before, then H75 (3rd, 4th), H76, H77
(``../shared/protocol/mitsubishi-fr700.md``, "Fault history"). An empty
slot reads 00.

Decisions: the code table is the reference's, display name and meaning
(the A700/F700/E700/D700 manuals' alarm-data table, where the reference
marks several rows as recalled, not re-read); a code it does not list is
kept, named ``unknown (0xNN)`` (later firmware and the 800 series add
codes), never refused. ``E.n`` codes are H(F0 + n).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from ..wire import RemoteProtocolError

__all__ = [
    "FAULT_HISTORY_DEPTH",
    "Fr700Fault",
    "Fr700FaultHistory",
    "decode_fault_history",
    "known_fault_codes",
]

#: Trips the drive keeps (H74..H77, two each).
FAULT_HISTORY_DEPTH: Final = 8

_FAULTS: Final[dict[int, tuple[str, str]]] = {
    0x10: ("E.OC1", "overcurrent trip during acceleration"),
    0x11: ("E.OC2", "overcurrent trip during constant speed"),
    0x12: ("E.OC3", "overcurrent trip during deceleration or stop"),
    0x20: ("E.OV1", "regenerative overvoltage trip during acceleration"),
    0x21: ("E.OV2", "regenerative overvoltage trip during constant speed"),
    0x22: ("E.OV3", "regenerative overvoltage trip during deceleration or stop"),
    0x30: ("E.THT", "inverter overload trip (electronic thermal relay)"),
    0x31: ("E.THM", "motor overload trip (electronic thermal relay)"),
    0x40: ("E.FIN", "heatsink (fin) overheat"),
    0x50: ("E.IPF", "instantaneous power failure"),
    0x51: ("E.UVT", "undervoltage"),
    0x52: ("E.ILF", "input phase loss"),
    0x60: ("E.OLT", "stall prevention stop"),
    0x70: ("E.BE", "brake transistor alarm detection"),
    0x80: ("E.GF", "output side earth (ground) fault overcurrent"),
    0x81: ("E.LF", "output phase loss"),
    0x90: ("E.OHT", "external thermal relay operation (OH input)"),
    0x91: ("E.PTC", "PTC thermistor operation"),
    0xA0: ("E.OPT", "option fault"),
    0xA1: ("E.OP1", "communication option fault, slot 1"),
    0xA2: ("E.OP2", "communication option fault, slot 2"),
    0xA3: ("E.OP3", "communication option fault, slot 3"),
    0xB0: ("E.PE", "parameter storage device fault (control board)"),
    0xB1: ("E.PUE", "PU disconnection"),
    0xB2: ("E.RET", "retry count excess"),
    0xB3: ("E.PE2", "parameter storage device fault (main circuit board)"),
    0xC0: ("E.CPU", "CPU fault"),
    0xC1: ("E.CTE", "operation panel / RS-485 terminal power supply short circuit"),
    0xC2: ("E.P24", "24 VDC power output short circuit"),
    0xC4: ("E.CDO", "output current detection value exceeded"),
    0xC5: ("E.IOH", "inrush current limit circuit fault"),
    0xC6: ("E.SER", "communication fault (inverter RS-485 terminals)"),
    0xC7: ("E.AIE", "analog input fault"),
    0xC8: ("E.USB", "USB communication fault"),
    0xC9: ("E.SAF", "safety circuit fault"),
    0xD0: ("E.OS", "overspeed occurrence"),
    0xD1: ("E.OSD", "speed deviation excess"),
    0xD2: ("E.ECT", "encoder signal loss"),
    0xD3: ("E.OD", "excessive position error"),
    **{0xD5 + i: (f"E.MB{i + 1}", f"brake sequence fault {i + 1}") for i in range(7)},
    0xDC: ("E.EP", "encoder phase fault"),
    0xE4: ("E.LCI", "4 mA input loss"),
    0xE5: ("E.PCH", "precharge fault"),
    0xE6: ("E.PID", "PID signal fault"),
    **{0xF0 + n: (f"E.{n}", f"option fault, slot {n}") for n in (1, 2, 3)},
    0xF5: ("E.5", "CPU fault"),
    0xF6: ("E.6", "CPU fault"),
    0xF7: ("E.7", "CPU fault"),
    0xFB: ("E.11", "opposite rotation deceleration fault"),
    0xFD: ("E.13", "internal circuit fault"),
}


@dataclass(frozen=True, slots=True)
class Fr700Fault:
    """One recorded trip: its code byte, display name (``E.OC1``) and meaning."""

    code: int
    display: str
    meaning: str | None

    @classmethod
    def of(cls, code: int) -> Fr700Fault:
        """The fault of code byte *code* (0x01..0xFF), named when the table lists it."""
        if not 0 < code <= 0xFF:
            raise ValueError(f"a fault code is 0x01..0xFF, got {code!r}")
        display, meaning = _FAULTS.get(code, (f"unknown (0x{code:02X})", None))
        return cls(code, display, meaning)

    def __str__(self) -> str:
        return self.display if self.meaning is None else f"{self.display} {self.meaning}"


@dataclass(frozen=True, slots=True)
class Fr700FaultHistory:
    """The drive's recorded trips, most recent first (at most eight; empty slots left out)."""

    faults: tuple[Fr700Fault, ...]

    @property
    def latest(self) -> Fr700Fault | None:
        """The most recent trip, None when none is recorded."""
        return self.faults[0] if self.faults else None


def decode_fault_history(words: Sequence[int]) -> Fr700FaultHistory:
    """The history from the four replies of H74..H77, in that order.

    Raises:
        RemoteProtocolError: not four 16-bit values.
    """
    if len(words) != FAULT_HISTORY_DEPTH // 2 or any(not 0 <= w <= 0xFFFF for w in words):
        raise RemoteProtocolError(f"a fault history is four 16-bit words, got {list(words)!r}")
    codes = [byte for word in words for byte in (word & 0xFF, word >> 8)]
    return Fr700FaultHistory(tuple(Fr700Fault.of(code) for code in codes if code))


def known_fault_codes() -> tuple[int, ...]:
    """The fault codes the table names, in order."""
    return tuple(sorted(_FAULTS))
