"""The SJ300 command set: what each command sends, may it be broadcast, what it gets back."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from ._constants import MONITOR_DATA_LEN, STATUS_DATA_LEN, TRIP_HISTORY_DATA_LEN

__all__ = [
    "COMMAND_SPECS",
    "Command",
    "CommandSpec",
    "ReplyKind",
    "RequestData",
    "reply_frame_length",
    "shortest_reply_frame_length",
]


class Command(enum.IntEnum):
    """Command numbers; the value is the number sent as two hex characters ("0A" = 10)."""

    #: 00: run forward / reverse, or stop.
    RUN = 0x00
    #: 01: set the output frequency of the standard profile (Hz x 100).
    SET_FREQUENCY = 0x01
    #: 02: set the intelligent input terminals (16 hex digits bit mask).
    SET_TERMINALS = 0x02
    #: 03: read the whole monitor block (104 characters).
    READ_MONITOR = 0x03
    #: 04: read the inverter status A/B/C (8 characters).
    READ_STATUS = 0x04
    #: 05: read the trip history (440 characters).
    READ_TRIP_HISTORY = 0x05
    #: 06: read one parameter (4-character code -> ACK + 8 digits).
    READ_PARAMETER = 0x06
    #: 07: write one parameter (code + 8 digits).
    WRITE_PARAMETER = 0x07
    #: 08: initialize to factory defaults (mode B084, country B085).
    INITIALIZE = 0x08
    #: 09: may a setting be stored to EEPROM? (ACK + "00"/"01").
    CAN_STORE = 0x09
    #: 0A: store the settings to EEPROM.
    STORE = 0x0A
    #: 0B: recalculate the internal motor constants.
    RECALCULATE = 0x0B

    @property
    def wire(self) -> bytes:
        """The two ASCII characters on the wire, e.g. ``b"0A"``."""
        return _WIRE[self]

    @property
    def spec(self) -> CommandSpec:
        """What the protocol allows for this command."""
        return COMMAND_SPECS[self]


_WIRE: dict[Command, bytes] = {c: b"%02X" % c.value for c in Command}


class RequestData(enum.Enum):
    """Shape of a request's data field."""

    #: No data.
    NONE = "none"
    #: One character, ``0`` stop, ``1`` forward, ``2`` reverse.
    RUN_MODE = "run mode"
    #: Six decimal digits, Hz x 100.
    FREQUENCY = "frequency"
    #: Sixteen hex digits, only assigned terminal bits.
    TERMINALS = "terminals"
    #: A 4-character parameter code.
    PARAMETER_CODE = "parameter code"
    #: A 4-character parameter code followed by eight decimal digits.
    PARAMETER_VALUE = "parameter code + value"


class ReplyKind(enum.Enum):
    """Shape of the reply a command gets."""

    #: ``STX node ACK BCC CR``
    ACK = "ack"
    #: ``STX node ACK data BCC CR``
    ACK_DATA = "ack + data"
    #: ``STX node data BCC CR``
    DATA = "data"


@dataclass(frozen=True, slots=True)
class CommandSpec:
    """The rules for one command."""

    #: Shape of the data the host sends.
    request: RequestData
    #: May the command go to node FF (all drives, no reply)?
    broadcast: bool
    #: Shape of the drive's positive reply.
    reply: ReplyKind
    #: Number of data characters in the positive reply (after ACK for ACK_DATA).
    reply_length: int = 0


COMMAND_SPECS: dict[Command, CommandSpec] = {
    Command.RUN: CommandSpec(RequestData.RUN_MODE, True, ReplyKind.ACK),
    Command.SET_FREQUENCY: CommandSpec(RequestData.FREQUENCY, True, ReplyKind.ACK),
    Command.SET_TERMINALS: CommandSpec(RequestData.TERMINALS, True, ReplyKind.ACK),
    Command.READ_MONITOR: CommandSpec(RequestData.NONE, False, ReplyKind.DATA, MONITOR_DATA_LEN),
    Command.READ_STATUS: CommandSpec(RequestData.NONE, False, ReplyKind.DATA, STATUS_DATA_LEN),
    Command.READ_TRIP_HISTORY: CommandSpec(
        RequestData.NONE, False, ReplyKind.DATA, TRIP_HISTORY_DATA_LEN
    ),
    Command.READ_PARAMETER: CommandSpec(RequestData.PARAMETER_CODE, False, ReplyKind.ACK_DATA, 8),
    Command.WRITE_PARAMETER: CommandSpec(RequestData.PARAMETER_VALUE, True, ReplyKind.ACK),
    Command.INITIALIZE: CommandSpec(RequestData.NONE, True, ReplyKind.ACK),
    Command.CAN_STORE: CommandSpec(RequestData.NONE, False, ReplyKind.ACK_DATA, 2),
    Command.STORE: CommandSpec(RequestData.NONE, True, ReplyKind.ACK),
    # The command table lists 0B as not broadcastable (its frame allows 01..32 only).
    Command.RECALCULATE: CommandSpec(RequestData.NONE, False, ReplyKind.ACK),
}


# Frame lengths STX..CR: ACK reply 7, NAK reply 9.
_ACK_FRAME = 7


_NAK_FRAME = 9


def _positive_frame_length(command: Command) -> int:
    spec = command.spec
    if spec.reply is ReplyKind.ACK:
        return _ACK_FRAME
    if spec.reply is ReplyKind.ACK_DATA:
        return _ACK_FRAME + spec.reply_length
    return 6 + spec.reply_length


def reply_frame_length(command: Command) -> int:
    """Length of the longest reply (positive or NAK) the command can get, STX to CR."""
    return max(_positive_frame_length(command), _NAK_FRAME)


def shortest_reply_frame_length(command: Command) -> int:
    """Length of the shortest reply (positive or NAK) the command can get, STX to CR."""
    return min(_positive_frame_length(command), _NAK_FRAME)
