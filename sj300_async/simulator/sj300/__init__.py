"""Simulated Hitachi SJ300 drives on a simulated line (sans-IO; time is passed in as ``now``)."""

from __future__ import annotations

from ...sj300._codes import TripCode
from ._bus import SimulatedBus, SimulatorStats, simulate
from ._drive import DEFAULT_EEPROM_WRITE_S, DEFAULT_PROCESSING_S, SimulatedDrive
from ._parameters_table import Country

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
