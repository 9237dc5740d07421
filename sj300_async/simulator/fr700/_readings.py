"""What a simulated FR-700 reports: its status bits, its monitors, its fault codes.

Pure functions of the drive's run state, output and parameters
(:mod:`._drive` holds the state): H7A's status bits, and the monitors
H6F / H70 / H71 from the electrical model shared with the SJ300 simulator
(rated current Pr.9, 200 V class, base frequency Pr.3).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

from ...fr700.codec import Fr700StatusBits
from ...wire import Direction
from .._electrical import MotorRating, electrical
from .._motion import Output, RunState

__all__ = ["FaultCode", "monitor", "status_bits"]

_RATED_VOLTAGE_V: Final = 200.0
_RATED_POWER_KW: Final = 2.2


class FaultCode:
    """Fault codes a simulated drive records (the FR-A700 list's codes)."""

    OC1: Final = 0x10  #: E.OC1 over-current during acceleration
    OC2: Final = 0x11  #: E.OC2 over-current during constant speed
    OC3: Final = 0x12  #: E.OC3 over-current during deceleration or stop
    OV1: Final = 0x20  #: E.OV1 regenerative over-voltage during acceleration
    THT: Final = 0x30  #: E.THT inverter overload (0x90 is E.OHT, the external thermal relay)
    PUE: Final = 0xB1  #: E.PUE PU disconnection


def status_bits(
    state: RunState, output: Output, fu_centi_hz: int, tripped: bool
) -> Fr700StatusBits:
    """RUN, forward, reverse, SU (at the set frequency), FU (output at or above
    *fu_centi_hz*, Pr.42), and ABC1 with the fault bit while *tripped*."""
    bits = Fr700StatusBits(0)
    if state.outputting:
        bits |= Fr700StatusBits.RUN
        if output.direction is Direction.FORWARD:
            bits |= Fr700StatusBits.FORWARD
        elif output.direction is Direction.REVERSE:
            bits |= Fr700StatusBits.REVERSE
        if state is RunState.CONSTANT_SPEED:
            bits |= Fr700StatusBits.SU
        if output.hz * 100 >= fu_centi_hz:
            bits |= Fr700StatusBits.FU
    if tripped:
        bits |= Fr700StatusBits.ABC1 | Fr700StatusBits.FAULT
    return bits


def monitor(
    selection: int,
    state: RunState,
    output: Output,
    set_centi_hz: int,
    parameters: Mapping[int, int],
) -> int:
    """A monitor value in link units: 1 frequency, 2 current, 3 voltage, 5 set frequency."""
    if selection == 5:
        return set_centi_hz
    if selection == 1:
        return round(output.hz * 100)
    rating = MotorRating(
        voltage_v=_RATED_VOLTAGE_V,
        current_a=parameters[9] / 100,
        power_kw=_RATED_POWER_KW,
        base_hz=parameters[3] / 100 or 60.0,
    )
    values = electrical(state, output.hz, rating)
    if selection == 2:
        return round(values.current_a * 100)
    return round(values.voltage_v * 10)
