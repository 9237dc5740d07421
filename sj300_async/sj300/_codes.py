"""Enumerations of the codes drives send: status A/B/C, trip-record fields, NAK error codes.

Every enum here is *tolerant*: a code the manual does not list (newer
firmware, option cards) becomes a pseudo-member named ``UNKNOWN_<n>`` instead
of an exception, so a decoder never fails on a well-formed number it has not
heard of, and the value is kept.
"""

from __future__ import annotations

import enum

from ..wire._enums import TolerantIntEnum

__all__ = [
    "NakCode",
    "StatusA",
    "StatusB",
    "StatusC",
    "TripStatusB",
    "TripStatusC",
]


class StatusA(TolerantIntEnum):
    """Status A (command 04 and trip records): the drive's operating state."""

    INITIAL = 0  #: initial status
    STOPPING = 2  #: on stopping
    RUNNING = 3  #: on running
    FREE_RUN_STOP = 4  #: on free-run stop
    JOGGING = 5  #: on jog
    DYNAMIC_BRAKING = 6  #: on dynamic braking
    RETRY = 7  #: on retry
    TRIP = 8  #: on trip
    UNDER_VOLTAGE = 9  #: on under-voltage


class StatusB(TolerantIntEnum):
    """Status B (command 04): stopped, running or tripped."""

    STOPPED = 0  #: on stopping
    RUNNING = 1  #: on running
    TRIPPED = 2  #: on tripping


class StatusC(TolerantIntEnum):
    """Status C (command 04): what the output is doing."""

    STOP = 1  #: stop
    DECELERATING = 2  #: decelerating
    CONSTANT_SPEED = 3  #: constant speed
    ACCELERATING = 4  #: accelerating
    FORWARD = 5  #: forward
    REVERSE = 6  #: reverse
    REVERSE_FROM_FORWARD = 7  #: reverse from forward
    FORWARD_FROM_REVERSE = 8  #: forward from reverse
    FORWARD_START = 9  #: forward start
    REVERSE_START = 10  #: reverse start


class TripStatusC(TolerantIntEnum):
    """Status C as recorded in a trip-history record (a different table than command 04's)."""

    RESET = 0  #: on reset
    STOPPING = 1  #: on stopping
    DECELERATING = 2  #: on deceleration
    CONSTANT_SPEED = 3  #: constant speed
    ACCELERATING = 4  #: on acceleration
    ZERO_HZ_RUN = 5  #: on 0 Hz running
    RUNNING = 6  #: on running
    DYNAMIC_BRAKING = 7  #: on dynamic braking
    OVERLOAD_RESTRICTION = 8  #: on overload restriction


class TripStatusB(enum.IntFlag):
    """Status B of a trip record: a bit field of hardware causes (with the E-code each implies)."""

    GROUND_FAULT = 1 << 0  #: E14
    IGBT_U = 1 << 1  #: E30
    UNDER_VOLTAGE = 1 << 2  #: E09
    OVER_VOLTAGE = 1 << 3  #: E07
    THERMAL = 1 << 4  #: E21
    IGBT_V = 1 << 5  #: E30
    IGBT_W = 1 << 6  #: E30
    GATE_ARRAY = 1 << 7  #: E23


_NAK_DESCRIPTIONS = {
    1: "parity error",
    2: "check sum (BCC) error",
    3: "framing error",
    4: "overrun error",
    5: "protocol error",
    6: "ASCII code error",
    7: "receive buffer overrun",
    8: "receive time-out",
    11: "abnormal command code",
    13: "execution disabled",
    16: "abnormal parameter code or value",
}


class NakCode(TolerantIntEnum):
    """Error code of a negative reply (two decimal digits after NAK)."""

    PARITY = 1  #: parity error
    CHECKSUM = 2  #: the drive computed another BCC than the request carried
    FRAMING = 3  #: framing error
    OVERRUN = 4  #: UART overrun
    PROTOCOL = 5  #: wrong data length or structure
    ASCII = 6  #: a character that is not allowed
    RECEIVE_BUFFER_OVERRUN = 7  #: receive buffer overrun
    RECEIVE_TIMEOUT = 8  #: the request stalled mid-frame
    ABNORMAL_COMMAND = 11  #: unknown command
    EXECUTION_DISABLED = 13  #: the drive's settings forbid this command now
    ABNORMAL_PARAMETER = 16  #: unknown parameter code or value out of range

    @property
    def description(self) -> str:
        """The manual's meaning of the code."""
        return _NAK_DESCRIPTIONS.get(self.value, "unknown error code")

    @property
    def is_transmission_error(self) -> bool:
        """True for 01..08: the request was damaged on the way, so sending it again may work.

        11, 13 and 16 are the drive's verdict on the request itself: retrying
        cannot change it.
        """
        return 1 <= self.value <= 8
