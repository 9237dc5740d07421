"""Terminal bit masks: command 02's input terminals and the monitor block's terminal items."""

from __future__ import annotations

import enum

__all__ = ["ASSIGNED_INPUT_BITS", "InputMonitor", "InputTerminal", "OutputTerminal"]


class InputTerminal(enum.IntFlag):
    """Intelligent input terminal functions set by command 02 (names are the manual's symbols).

    Combine with ``|``: ``InputTerminal.FW | InputTerminal.CF1``. Bits 10, 19,
    25, 30 and 49..63 are unassigned; the request encoder refuses them.
    """

    FW = 1 << 0  #: forward run
    RV = 1 << 1  #: reverse run
    CF1 = 1 << 2  #: multi-speed select 1
    CF2 = 1 << 3  #: multi-speed select 2
    CF3 = 1 << 4  #: multi-speed select 3
    CF4 = 1 << 5  #: multi-speed select 4
    JG = 1 << 6  #: jogging
    DB = 1 << 7  #: external dynamic braking
    SET = 1 << 8  #: 2nd motor constants
    TWO_CH = 1 << 9  #: "2CH", 2-stage acceleration / deceleration
    FRS = 1 << 11  #: free-run stop
    EXT = 1 << 12  #: external trip
    USP = 1 << 13  #: unattended start protection
    CS = 1 << 14  #: commercial power source change
    SFT = 1 << 15  #: software lock
    AT = 1 << 16  #: analog input voltage / current select
    SET3 = 1 << 17  #: 3rd motor constants
    RS = 1 << 18  #: reset
    STA = 1 << 20  #: 3-wire start
    STP = 1 << 21  #: 3-wire hold
    FR = 1 << 22  #: "F/R", 3-wire forward / reverse
    PID = 1 << 23  #: PID enable
    PIDC = 1 << 24  #: PID integrator reset
    CAS = 1 << 26  #: control gain switching
    UP = 1 << 27  #: remote control increment
    DWN = 1 << 28  #: remote control decrement
    UDC = 1 << 29  #: clear remote up / down data
    OPE = 1 << 31  #: force operation from the operator
    SF1 = 1 << 32  #: multi-speed bit 1
    SF2 = 1 << 33  #: multi-speed bit 2
    SF3 = 1 << 34  #: multi-speed bit 3
    SF4 = 1 << 35  #: multi-speed bit 4
    SF5 = 1 << 36  #: multi-speed bit 5
    SF6 = 1 << 37  #: multi-speed bit 6
    SF7 = 1 << 38  #: multi-speed bit 7
    OLR = 1 << 39  #: overload restriction select
    TL = 1 << 40  #: torque limit enable
    TRQ1 = 1 << 41  #: torque limit select 1
    TRQ2 = 1 << 42  #: torque limit select 2
    PPI = 1 << 43  #: P / PI mode select
    BOK = 1 << 44  #: brake confirmation
    ORT = 1 << 45  #: orientation
    LAC = 1 << 46  #: linear accel / decel cancel
    PCLR = 1 << 47  #: position error clear
    STAT = 1 << 48  #: pulse train input enable


#: Every bit command 02 may carry.
ASSIGNED_INPUT_BITS: int = 0
for _member in InputTerminal:
    ASSIGNED_INPUT_BITS |= _member.value


class InputMonitor(enum.IntFlag):
    """Monitor item 5: state of the physical input terminals (read as hex)."""

    FW = 1 << 0  #: the FW terminal
    IN1 = 1 << 1  #: intelligent input 1
    IN2 = 1 << 2  #: intelligent input 2
    IN3 = 1 << 3  #: intelligent input 3
    IN4 = 1 << 4  #: intelligent input 4
    IN5 = 1 << 5  #: intelligent input 5
    IN6 = 1 << 6  #: intelligent input 6
    IN7 = 1 << 7  #: intelligent input 7
    IN8 = 1 << 8  #: intelligent input 8


class OutputTerminal(enum.IntFlag):
    """Monitor item 6: state of the intelligent output terminals (read as hex)."""

    AL = 1 << 0  #: alarm relay
    OUT11 = 1 << 1  #: output terminal 11
    OUT12 = 1 << 2  #: output terminal 12
    OUT13 = 1 << 3  #: output terminal 13
    OUT14 = 1 << 4  #: output terminal 14
    OUT15 = 1 << 5  #: output terminal 15
