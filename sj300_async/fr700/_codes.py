"""Control bytes, instruction codes and the codes FR-700 drives send.

Facts come from the FR-700 reference (``shared/protocol/mitsubishi-fr700.md``):
the seed page of the FR-A700 manual plus the public FR-A700 / F700 / E700
manuals for the instruction codes the seed does not show.

Decisions where the reference is silent:

- NAK code 0 ("too many consecutive errors") is *not* a transmission error
  for retrying: the drive has already tripped (E.PUE / E.SER), so sending
  the request again cannot succeed. Codes 1, 2, 3, 4, 5 and 7 are damage on
  the way and are worth a retry; A, B and C are the drive's verdict on the
  request itself.
- Codes 6, 8, 9, D and E are not listed; like SJ300's codes they become
  ``UNKNOWN_<n>`` pseudo-members instead of an exception.
- The extended status (H79) adds ABC2 (b8) and "fault occurred" (b15) to the
  eight bits of H7A; bits 9..14 are not named by the reference and are kept
  as they come.
"""

from __future__ import annotations

import enum
from typing import Final

from ..wire import TolerantIntEnum as TolerantIntEnum

__all__ = [
    "A1_INSTRUCTIONS",
    "ACK",
    "CR",
    "ENQ",
    "ETX",
    "LF",
    "NAK",
    "RESET_DATA",
    "STX",
    "Fr700Instruction",
    "Fr700NakCode",
    "Fr700OperationMode",
    "Fr700StatusBits",
]

STX: Final = 0x02  #: start of a data reply (E, E1, E2, E3, C1)
ETX: Final = 0x03  #: end of the data of a reply
ENQ: Final = 0x05  #: start of a request (A, A1, A2, B)
ACK: Final = 0x06  #: positive reply (C), or the host's "reply received" (C)
LF: Final = 0x0A  #: optional second terminator
CR: Final = 0x0D  #: optional terminator
NAK: Final = 0x15  #: negative reply (D), or the host's "send it again" (F)

#: The data of the inverter reset (HFD) and of the clear requests (HF4, HFC).
RESET_DATA: Final = 0x9696


class Fr700Instruction(enum.IntEnum):
    """Instruction codes with a name. Reads are H00..H7F, the matching write is +H80."""

    #: H00..H63 read parameter offset 0..99 of the selected bank (the first of the range).
    READ_PARAMETER = 0x00
    #: H6C: read the second-parameter (bias/gain) switch.
    READ_SECOND_PARAMETER = 0x6C
    #: H6D: read the set frequency in RAM (x 0.01 Hz).
    READ_SET_FREQUENCY_RAM = 0x6D
    #: H6E: read the set frequency in EEPROM (x 0.01 Hz).
    READ_SET_FREQUENCY_EEPROM = 0x6E
    #: H6F: output frequency monitor (x 0.01 Hz).
    OUTPUT_FREQUENCY = 0x6F
    #: H70: output current monitor (x 0.01 A).
    OUTPUT_CURRENT = 0x70
    #: H71: output voltage monitor (x 0.1 V).
    OUTPUT_VOLTAGE = 0x71
    #: H73: read the special-monitor selection.
    READ_SPECIAL_MONITOR_SELECTION = 0x73
    #: H74..H77: fault history (the first of the range).
    FAULT_HISTORY = 0x74
    #: H79: extended status monitor (16 bits).
    EXTENDED_STATUS = 0x79
    #: H7A: status monitor (8 bits).
    STATUS = 0x7A
    #: H7B: read the operation mode.
    READ_OPERATION_MODE = 0x7B
    #: H7F: read the link-parameter extension (the parameter bank).
    READ_LINK_EXTENSION = 0x7F
    #: H80..HE3 write parameter offset 0..99 of the selected bank (the first of the range).
    WRITE_PARAMETER = 0x80
    #: HEC: write the second-parameter (bias/gain) switch.
    WRITE_SECOND_PARAMETER = 0xEC
    #: HED: write the set frequency to RAM.
    WRITE_SET_FREQUENCY_RAM = 0xED
    #: HEE: write the set frequency to RAM and EEPROM.
    WRITE_SET_FREQUENCY_EEPROM = 0xEE
    #: HF0: multi-command (format A2, reply C1).
    MULTI_COMMAND = 0xF0
    #: HF3: write the special-monitor selection.
    WRITE_SPECIAL_MONITOR_SELECTION = 0xF3
    #: HF4: clear the fault history (data H9696).
    CLEAR_FAULT_HISTORY = 0xF4
    #: HF9: extended run command (4 digits).
    EXTENDED_RUN_COMMAND = 0xF9
    #: HFA: run command (2 digits: H00 stop, H02 forward, H04 reverse).
    RUN_COMMAND = 0xFA
    #: HFB: write the operation mode.
    WRITE_OPERATION_MODE = 0xFB
    #: HFC: parameter clear / all clear (H9696, H9966, H5A5A, H55AA).
    PARAMETER_CLEAR = 0xFC
    #: HFD: inverter reset (data H9696; the drive does not reply).
    INVERTER_RESET = 0xFD
    #: HFF: write the link-parameter extension (the parameter bank).
    WRITE_LINK_EXTENSION = 0xFF


#: Writes whose data is two digits (format A1); every other write has four (format A),
#: except the multi-command HF0 (format A2).
A1_INSTRUCTIONS: Final = frozenset(
    {
        Fr700Instruction.RUN_COMMAND,
        Fr700Instruction.WRITE_LINK_EXTENSION,
        Fr700Instruction.WRITE_SECOND_PARAMETER,
        Fr700Instruction.WRITE_SPECIAL_MONITOR_SELECTION,
    }
)

_NAK_DESCRIPTIONS: Final = {
    0x0: "computer NAK error: too many consecutive errors",
    0x1: "parity error",
    0x2: "sum check error",
    0x3: "protocol error",
    0x4: "framing error",
    0x5: "overrun error",
    0x7: "character error",
    0xA: "mode error",
    0xB: "instruction code error",
    0xC: "data range error",
    0xF: "no error",
}


class Fr700NakCode(TolerantIntEnum):
    """The one hex character after NAK (format D), or an error field of a C1 reply."""

    COMPUTER_NAK = 0x0  #: too many consecutive errors: the drive trips E.PUE / E.SER
    PARITY = 0x1  #: parity error
    SUM_CHECK = 0x2  #: the drive computed another sum than the request carried
    PROTOCOL = 0x3  #: bad grammar, frame incomplete in time, CR/LF mismatch
    FRAMING = 0x4  #: stop bit error
    OVERRUN = 0x5  #: the drive received before it had processed the previous character
    CHARACTER = 0x7  #: a character that is not 0-9, A-F or a control code
    MODE = 0xA  #: writing is not allowed in this operation mode, or while running
    INSTRUCTION_CODE = 0xB  #: no such instruction code
    DATA_RANGE = 0xC  #: the data is out of range
    NO_ERROR = 0xF  #: (multi-command replies only) this half of the request succeeded

    @property
    def description(self) -> str:
        """The reference's meaning of the code."""
        return _NAK_DESCRIPTIONS.get(self.value, "unknown error code")

    @property
    def is_transmission_error(self) -> bool:
        """True when the request was damaged on the way: sending it again may work."""
        return self.value in (0x1, 0x2, 0x3, 0x4, 0x5, 0x7)

    @property
    def wire(self) -> bytes:
        """The code as its one hex character, ``b"A"``."""
        return b"%X" % self.value


class Fr700OperationMode(TolerantIntEnum):
    """Operation mode, the data of H7B / HFB."""

    NETWORK = 0x0000  #: network (computer link) operation
    EXTERNAL = 0x0001  #: external (terminal) operation
    PU = 0x0002  #: operation panel / parameter unit


class Fr700StatusBits(enum.IntFlag):
    """The status monitor: H7A is bits 0..7, H79 all sixteen."""

    RUN = 1 << 0  #: the inverter is running (outputting)
    FORWARD = 1 << 1  #: forward rotation
    REVERSE = 1 << 2  #: reverse rotation
    SU = 1 << 3  #: up to frequency: the output has reached the set frequency
    OL = 1 << 4  #: overload (stall prevention active)
    IPF = 1 << 5  #: instantaneous power failure / undervoltage
    FU = 1 << 6  #: output frequency detection (at or above Pr.42)
    ABC1 = 1 << 7  #: fault output (relay ABC1)
    ABC2 = 1 << 8  #: (H79 only) relay ABC2
    FAULT = 1 << 15  #: (H79 only) a fault has occurred
