"""Simulated Hitachi SJ300 drives on a simulated line (sans-IO; time is passed in as ``now``)."""

from __future__ import annotations

from ._bus import SimulatedBus, SimulatorStats, simulate
from ._drive import DEFAULT_EEPROM_WRITE_S, DEFAULT_PROCESSING_S, SimulatedDrive
from ._parameters_table import Country
from ._trips import TripCode

__all__ = [
    "DEFAULT_EEPROM_WRITE_S",
    "DEFAULT_PROCESSING_S",
    "Country",
    "SimulatedBus",
    "SimulatedDrive",
    "SimulatorStats",
    "TripCode",
    "simulate",
]
