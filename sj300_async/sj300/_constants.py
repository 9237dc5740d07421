"""Control bytes and frame-size limits of the SJ300 ASCII protocol."""

from __future__ import annotations

from typing import Final

STX: Final = 0x02  #: start of a frame
ACK: Final = 0x06  #: positive reply marker
NAK: Final = 0x15  #: negative reply marker
CR: Final = 0x0D  #: end of a frame

STX_BYTE: Final = b"\x02"
ACK_BYTE: Final = b"\x06"
NAK_BYTE: Final = b"\x15"
CR_BYTE: Final = b"\r"

#: Node address that every drive on the line accepts ("FF" on the wire).
BROADCAST: Final = 0xFF
#: Highest unicast node address a drive can have (C072 = 1..32).
MAX_NODE: Final = 32
MIN_NODE: Final = 1

#: Lengths of the data part of the three data replies.
STATUS_DATA_LEN: Final = 8
MONITOR_DATA_LEN: Final = 104
TRIP_HISTORY_DATA_LEN: Final = 440

#: The longest legal reply body between STX and CR: node(2) + trip history + BCC(2).
#: Anything longer cannot be a reply, so a parser never buffers more than this.
MAX_REPLY_BODY: Final = 2 + TRIP_HISTORY_DATA_LEN + 2

#: The longest legal request body between STX and CR: node + "02" + 16 hex digits + BCC
#: (command 07's code + value is 12 characters, four fewer).
MAX_REQUEST_BODY: Final = 2 + 2 + 16 + 2
