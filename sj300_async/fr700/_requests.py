"""FR-700 requests: a validated frame plus what the bus needs to know about it.

:class:`Fr700Request` satisfies the stack's ``LineRequest`` (``node``,
``frame``, ``expects_reply``, ``label``) and carries the instruction, its
kind and the width of the data reply it expects. The builders below format
the digits and validate every argument first; nothing invalid is encoded.

Decisions where the reference is silent:

- A read's reply width is checked only when the instruction's width is
  known (:data:`READ_WIDTHS`); a raw read of another code accepts a data
  reply of any width (E, E1, E2, E3 alike).
- Frequencies go out in 0.01 Hz steps as four hex digits, so 0..655.35 Hz;
  the drive refuses anything above its maximum frequency (Pr.1) with NAK C.
- Parameters 0..999 are addressed through the link-parameter extension:
  bank ``number // 100`` (written with HFF), then offset ``number % 100``
  (read H00..H63, write H80..HE3).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Final

from ..wire import Direction, LocalProtocolError
from ._codec import DEFAULT_LINE_OPTIONS, Fr700LineOptions, encode_request
from ._codes import A1_INSTRUCTIONS, RESET_DATA, Fr700Instruction, Fr700OperationMode

__all__ = [
    "MAX_FREQUENCY_HZ",
    "MAX_PARAMETER",
    "READ_WIDTHS",
    "Fr700MultiReceive",
    "Fr700Request",
    "Fr700RequestKind",
    "centi_hz",
    "link_extension",
    "multi_command",
    "parameter_bank",
    "parse_instruction",
    "read",
    "read_parameter",
    "reset",
    "run",
    "run_bits",
    "set_frequency",
    "write",
    "write_operation_mode",
    "write_parameter",
]

#: The highest frequency four hex digits of 0.01 Hz carry.
MAX_FREQUENCY_HZ: Final = 655.35
#: The highest parameter number the link-parameter extension reaches (bank 9).
MAX_PARAMETER: Final = 999

I = Fr700Instruction  # noqa: E741 - a short alias keeps the tables readable

#: Data characters of the read replies whose width this library knows.
READ_WIDTHS: Final[dict[int, int]] = {
    I.STATUS: 2,
    I.EXTENDED_STATUS: 4,
    I.READ_OPERATION_MODE: 4,
    I.OUTPUT_FREQUENCY: 4,
    I.OUTPUT_CURRENT: 4,
    I.OUTPUT_VOLTAGE: 4,
    I.READ_SET_FREQUENCY_RAM: 4,
    I.READ_SET_FREQUENCY_EEPROM: 4,
    I.READ_LINK_EXTENSION: 2,
    I.READ_SECOND_PARAMETER: 2,
    I.READ_SPECIAL_MONITOR_SELECTION: 2,
    **dict.fromkeys(range(100), 4),  # parameters
}

_RUN_BITS: Final = {Direction.STOP: 0x00, Direction.FORWARD: 0x02, Direction.REVERSE: 0x04}


class Fr700RequestKind(enum.Enum):
    """What a request does, which decides its reply and whether it changes the drive."""

    READ = "read"  #: format B; the reply is data (E..E3) or NAK
    WRITE = "write"  #: format A / A1; the reply is ACK or NAK
    RESET = "reset"  #: HFD H9696: the drive resets and does not reply
    MULTI = "multi-command"  #: format A2; the reply is C1 or NAK


class Fr700MultiReceive(enum.IntEnum):
    """The receive data type of a multi-command: what its data2 reports."""

    OUTPUT_FREQUENCY = 0  #: output frequency, x 0.01 Hz
    OUTPUT_CURRENT = 1  #: output current, x 0.01 A
    OUTPUT_VOLTAGE = 2  #: output voltage, x 0.1 V
    SPECIAL_MONITOR = 3  #: the special monitor selected with HF3 (raw)


@dataclass(frozen=True, slots=True)
class Fr700Request:
    """A validated FR-700 request. Build it with the module's functions, not directly."""

    #: The addressed station, 0..31.
    station: int
    #: The instruction code, 0x00..0xFF.
    instruction: int
    kind: Fr700RequestKind
    #: The data field as sent (hex digits, no waiting-time character).
    data: bytes
    #: The whole frame, ENQ through the terminator.
    frame: bytes
    #: Data characters the reply must have (reads and multi-commands), None: any.
    reply_width: int | None = None
    #: False for a request that only selects something for a later one (the
    #: parameter bank before a read): it is not refused on a read-only bus.
    changes_drive: bool = True

    @property
    def node(self) -> int:
        """The station (the name the bus uses for every protocol)."""
        return self.station

    @property
    def expects_reply(self) -> bool:
        """False only for the inverter reset, which the drive never answers."""
        return self.kind is not Fr700RequestKind.RESET

    @property
    def label(self) -> str:
        """``"instruction H7A"``: a short name for messages."""
        return f"instruction H{self.instruction:02X}"

    @property
    def mutating(self) -> bool:
        """True when the request changes the drive (a read-only bus refuses it)."""
        return self.kind is not Fr700RequestKind.READ and self.changes_drive


def parse_instruction(code: int | str) -> int:
    """An instruction code from an int or text such as ``"H7A"``, ``"0x7A"`` or ``"7A"``.

    Raises:
        LocalProtocolError: not a code 0x00..0xFF.
    """
    if isinstance(code, str):
        text = code.strip().upper().removeprefix("0X").removeprefix("H")
        if len(text) != 2:
            raise LocalProtocolError(f"an instruction code is two hex digits, got {code!r}")
        try:
            code = int(text, 16)
        except ValueError:
            raise LocalProtocolError(f"an instruction code is hex, got {code!r}") from None
    if isinstance(code, bool) or not isinstance(code, int) or not 0 <= code <= 0xFF:
        raise LocalProtocolError(f"an instruction code is H00..HFF, got {code!r}")
    return code


def read(
    station: int,
    instruction: int | str,
    *,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
    reply_width: int | None = None,
) -> Fr700Request:
    """A read (format B) of any instruction H00..H7F.

    Args:
        reply_width: data characters the reply must have; default: the
            instruction's known width, else any.

    Raises:
        LocalProtocolError: bad station or code, or a write code (H80..HFF).
    """
    code = parse_instruction(instruction)
    if code >= 0x80:
        raise LocalProtocolError(f"H{code:02X} is a write code; reads are H00..H7F")
    if reply_width is None:
        reply_width = READ_WIDTHS.get(code)
    elif isinstance(reply_width, bool) or not isinstance(reply_width, int):
        raise LocalProtocolError(f"reply_width must be an int, got {reply_width!r}")
    elif not 1 <= reply_width <= 20:
        raise LocalProtocolError(f"reply_width is 1..20 characters, got {reply_width!r}")
    frame = encode_request(station, code, options=options)
    return Fr700Request(station, code, Fr700RequestKind.READ, b"", frame, reply_width)


def write(
    station: int,
    instruction: int | str,
    value: int,
    *,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
    digits: int | None = None,
    changes_drive: bool = True,
) -> Fr700Request:
    """A write (format A or A1) of *value* to any instruction H80..HFF but HF0.

    Args:
        digits: 2 (A1) or 4 (A); default: 2 for the instructions known to take
            two (:data:`~sj300_async.fr700.A1_INSTRUCTIONS`), else 4.

    Raises:
        LocalProtocolError: bad station or code, a read code, HF0 (use
            :func:`multi_command`), or a value that does not fit.
    """
    code = parse_instruction(instruction)
    if code < 0x80:
        raise LocalProtocolError(f"H{code:02X} is a read code; writes are H80..HFF")
    if code == I.MULTI_COMMAND:
        raise LocalProtocolError("HF0 is the multi-command: use multi_command()")
    if digits is None:
        digits = 2 if code in A1_INSTRUCTIONS else 4
    if digits not in (2, 4) or isinstance(digits, bool):
        raise LocalProtocolError(f"a write carries 2 or 4 hex digits, got {digits!r}")
    if isinstance(value, bool) or not isinstance(value, int):
        raise LocalProtocolError(f"the value must be an int, got {value!r}")
    if not 0 <= value < 16**digits:
        raise LocalProtocolError(f"H{code:02X} value must fit {digits} hex digits, got {value!r}")
    data = b"%0*X" % (digits, value)
    frame = encode_request(station, code, data, options=options)
    kind = Fr700RequestKind.RESET if code == I.INVERTER_RESET else Fr700RequestKind.WRITE
    return Fr700Request(station, code, kind, data, frame, changes_drive=changes_drive)


# -- typed builders ---------------------------------------------------------------------


def run_bits(direction: Direction | int) -> int:
    """The run-command bits of *direction*: H00 stop, H02 forward, H04 reverse.

    Raises:
        LocalProtocolError: not STOP, FORWARD or REVERSE.
    """
    try:
        return _RUN_BITS[Direction(direction)]
    except (ValueError, KeyError):
        raise LocalProtocolError(
            f"direction must be STOP, FORWARD or REVERSE, got {direction!r}"
        ) from None


def run(
    station: int, direction: Direction | int, *, options: Fr700LineOptions = DEFAULT_LINE_OPTIONS
) -> Fr700Request:
    """HFA: run forward (H02), run reverse (H04) or stop (H00)."""
    return write(station, I.RUN_COMMAND, run_bits(direction), options=options)


def centi_hz(hz: float) -> int:
    """*hz* in 0.01 Hz steps, checked.

    Raises:
        LocalProtocolError: not a finite number in 0..655.35 or finer than 0.01 Hz.
    """
    if isinstance(hz, bool) or not isinstance(hz, int | float) or not math.isfinite(hz):
        raise LocalProtocolError(f"frequency must be a number of Hz, got {hz!r}")
    if not 0 <= hz <= MAX_FREQUENCY_HZ:
        raise LocalProtocolError(f"frequency must be within 0..{MAX_FREQUENCY_HZ} Hz, got {hz!r}")
    centi = round(hz * 100)
    if abs(centi - hz * 100) > 1e-6:
        raise LocalProtocolError(f"frequency has a resolution of 0.01 Hz, got {hz!r}")
    return centi


def set_frequency(
    station: int,
    hz: float,
    *,
    eeprom: bool = False,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
) -> Fr700Request:
    """HED (RAM) or HEE (RAM and EEPROM): the set frequency in Hz, 0.01 Hz steps."""
    code = I.WRITE_SET_FREQUENCY_EEPROM if eeprom else I.WRITE_SET_FREQUENCY_RAM
    return write(station, code, centi_hz(hz), options=options)


def write_operation_mode(
    station: int,
    mode: Fr700OperationMode | int,
    *,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
) -> Fr700Request:
    """HFB: network, external or PU operation."""
    try:
        mode = Fr700OperationMode(mode)
    except ValueError:
        raise LocalProtocolError(
            f"operation mode must be an Fr700OperationMode, got {mode!r}"
        ) from None
    if not mode.known:
        raise LocalProtocolError(f"operation mode must be NETWORK, EXTERNAL or PU, got {mode!r}")
    return write(station, I.WRITE_OPERATION_MODE, int(mode), options=options)


def reset(station: int, *, options: Fr700LineOptions = DEFAULT_LINE_OPTIONS) -> Fr700Request:
    """HFD H9696: inverter reset (no reply)."""
    return write(station, I.INVERTER_RESET, RESET_DATA, options=options)


def parameter_bank(number: int | str) -> tuple[int, int]:
    """``(bank, offset)`` of a parameter number 0..999 (``"Pr.7"`` and ``"7"`` accepted).

    Raises:
        LocalProtocolError: not a parameter number 0..999.
    """
    if isinstance(number, str):
        text = number.strip().upper().removeprefix("PR").lstrip(".").strip()
        if not text.isdigit():
            raise LocalProtocolError(f"a parameter is a number 0..999 or 'Pr.N', got {number!r}")
        number = int(text)
    if isinstance(number, bool) or not isinstance(number, int):
        raise LocalProtocolError(f"a parameter number must be an int, got {number!r}")
    if not 0 <= number <= MAX_PARAMETER:
        raise LocalProtocolError(f"parameter numbers are 0..{MAX_PARAMETER}, got {number!r}")
    return divmod(number, 100)


def link_extension(
    station: int,
    bank: int,
    *,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
    changes_drive: bool = True,
) -> Fr700Request:
    """HFF: select the parameter bank (0: Pr.0..99, 1: Pr.100..199, ... 9: Pr.900..999)."""
    if isinstance(bank, bool) or not isinstance(bank, int) or not 0 <= bank <= 9:
        raise LocalProtocolError(f"a parameter bank is 0..9, got {bank!r}")
    return write(
        station, I.WRITE_LINK_EXTENSION, bank, options=options, changes_drive=changes_drive
    )


def read_parameter(
    station: int, number: int | str, *, options: Fr700LineOptions = DEFAULT_LINE_OPTIONS
) -> Fr700Request:
    """H00..H63: read parameter *number* in its bank (select the bank first with HFF)."""
    _bank, offset = parameter_bank(number)
    return read(station, offset, options=options)


def write_parameter(
    station: int,
    number: int | str,
    value: int,
    *,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
) -> Fr700Request:
    """H80..HE3: write *value* (0..65535) to parameter *number* in its bank."""
    _bank, offset = parameter_bank(number)
    return write(station, I.WRITE_PARAMETER + offset, value, options=options)


def multi_command(
    station: int,
    run_bits: int,
    hz: float,
    *,
    eeprom: bool = False,
    receive: Fr700MultiReceive | int = Fr700MultiReceive.OUTPUT_FREQUENCY,
    options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
) -> Fr700Request:
    """HF0 (format A2): run command and set frequency out, status and one monitor back.

    Args:
        run_bits: the extended run command (HF9 layout: H0002 forward, H0004 reverse).
        hz: the set frequency, written to RAM (and EEPROM with *eeprom*: send type 1).
        receive: which monitor comes back as data2.
    """
    if isinstance(run_bits, bool) or not isinstance(run_bits, int) or not 0 <= run_bits <= 0xFFFF:
        raise LocalProtocolError(f"run_bits must be an int 0..0xFFFF, got {run_bits!r}")
    try:
        receive = Fr700MultiReceive(receive)
    except ValueError:
        raise LocalProtocolError(f"receive must be a Fr700MultiReceive, got {receive!r}") from None
    data = b"%d%d%04X%04X" % (int(eeprom), receive, run_bits, centi_hz(hz))
    frame = encode_request(station, I.MULTI_COMMAND, data, options=options)
    return Fr700Request(station, I.MULTI_COMMAND, Fr700RequestKind.MULTI, data, frame, 12)
