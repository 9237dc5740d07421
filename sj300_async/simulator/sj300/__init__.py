"""Simulated Hitachi SJ300 drives on a simulated line (sans-IO; time is passed in as ``now``)."""

from __future__ import annotations

from ...sj300.codec import TripCode
from ._bus import SimulatedBus, SimulatorStats, simulate
from ._command_line import COMMAND_LINE
from ._drive import DEFAULT_EEPROM_WRITE_S, DEFAULT_PROCESSING_S, SimulatedDrive
from ._parameters_table import Country

__all__ = [
    "COMMAND_LINE",
    "DEFAULT_EEPROM_WRITE_S",
    "DEFAULT_PROCESSING_S",
    "Country",
    "SimulatedBus",
    "SimulatedDrive",
    "SimulatorStats",
    "TripCode",
    "simulate",
]
