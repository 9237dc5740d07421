"""Enumerations of the codes drives send: status A/B/C, trip codes and records, NAK codes.

Every enum here is *tolerant*: a code the manual does not list (newer
firmware, option cards) becomes a pseudo-member named ``UNKNOWN_<n>`` instead
of an exception, so a decoder never fails on a well-formed number it has not
heard of, and the value is kept.
"""

from __future__ import annotations

import enum

from ..wire import TolerantIntEnum

__all__ = [
    "NakCode",
    "StatusA",
    "StatusB",
    "StatusC",
    "TripCode",
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


_TRIP_DESCRIPTIONS = {
    1: "over-current at constant speed",
    2: "over-current while decelerating",
    3: "over-current while accelerating",
    4: "over-current (other)",
    5: "overload",
    6: "braking resistor overload",
    7: "over-voltage",
    8: "EEPROM error",
    9: "under-voltage",
    10: "CT error",
    11: "CPU error",
    12: "external trip",
    13: "USP (unattended start protection)",
    14: "ground fault",
    15: "input over-voltage",
    16: "momentary power failure",
    21: "thermal trip",
    23: "gate array error",
    24: "phase loss",
    30: "IGBT error",
    35: "thermistor",
    36: "brake error",
    **dict.fromkeys(range(60, 70), "option card error"),
}


class TripCode(TolerantIntEnum):
    """A trip factor: the number of the E-code on the drive's display (7 is E07).

    The SJ300 error codes commonly published (the reference has no table of
    its own); any other number is kept as an ``UNKNOWN_<n>`` pseudo-member.
    :attr:`description` is the meaning, :attr:`error_code` the display's text.
    """

    OVER_CURRENT_CONSTANT = 1  #: E01, over-current at constant speed
    OVER_CURRENT_DECEL = 2  #: E02, over-current while decelerating
    OVER_CURRENT_ACCEL = 3  #: E03, over-current while accelerating
    OVER_CURRENT_OTHER = 4  #: E04, over-current otherwise (stopped)
    OVERLOAD = 5  #: E05, overload
    BRAKING_RESISTOR_OVERLOAD = 6  #: E06, braking resistor overload
    OVER_VOLTAGE = 7  #: E07, over-voltage
    EEPROM = 8  #: E08, EEPROM error
    UNDER_VOLTAGE = 9  #: E09, under-voltage
    CT = 10  #: E10, current transformer error
    CPU = 11  #: E11, CPU error
    EXTERNAL = 12  #: E12, external trip (the EXT terminal)
    USP = 13  #: E13, unattended start protection
    GROUND_FAULT = 14  #: E14, ground fault
    INPUT_OVER_VOLTAGE = 15  #: E15, input over-voltage
    MOMENTARY_POWER_FAILURE = 16  #: E16, momentary power failure
    THERMAL = 21  #: E21, thermal trip
    GATE_ARRAY = 23  #: E23, gate array error
    PHASE_LOSS = 24  #: E24, input phase loss
    IGBT = 30  #: E30, IGBT error
    THERMISTOR = 35  #: E35, thermistor
    BRAKE = 36  #: E36, brake error
    OPTION_CARD_60 = 60  #: E60..E69, option card errors
    OPTION_CARD_61 = 61
    OPTION_CARD_62 = 62
    OPTION_CARD_63 = 63
    OPTION_CARD_64 = 64
    OPTION_CARD_65 = 65
    OPTION_CARD_66 = 66
    OPTION_CARD_67 = 67
    OPTION_CARD_68 = 68
    OPTION_CARD_69 = 69

    @property
    def description(self) -> str:
        """The meaning of the code (``"over-voltage"``); ``"unknown trip"`` when not listed."""
        return _TRIP_DESCRIPTIONS.get(self.value, "unknown trip")

    @property
    def error_code(self) -> str:
        """The code as the drive's display shows it: ``"E07"``."""
        return f"E{self.value:02d}"


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
