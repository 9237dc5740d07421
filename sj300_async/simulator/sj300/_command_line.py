"""The SJ300 simulator's part of ``sj300 simulate``: ``--country``, and its summary."""

from __future__ import annotations

from typing import Final

from .._command_line import SimulateOption, SimulateSettings
from ._bus import SimulatedBus
from ._drive import SimulatedDrive
from ._parameters_table import Country

__all__ = ["COMMAND_LINE"]

_COUNTRIES: Final = {"jp": Country.JAPAN, "eu": Country.EUROPE, "us": Country.USA}


class _CommandLine:
    title = "SJ300 drives (with --protocol sj300, the default)"
    options = (
        SimulateOption(
            "--country",
            "country",
            "B085 factory values: eu 50 Hz, us/jp 60 Hz (default eu)",
            choices=tuple(sorted(_COUNTRIES)),
            default="eu",
        ),
    )

    def build(self, settings: SimulateSettings) -> SimulatedBus:
        return SimulatedBus(
            settings.nodes,
            factory_defaults=settings.factory_defaults,
            country=_COUNTRIES[str(settings.options.get("country") or "eu")],
            wait_ms=settings.wait_ms,
            line=settings.line,
        )

    def describe(self, bus: SimulatedBus, settings: SimulateSettings) -> str:
        return "factory defaults" if settings.factory_defaults else "serial control"

    def trip_name(self, drive: SimulatedDrive) -> str:
        return drive.trip_history().records[0].error_code


#: Found by ``sj300 simulate`` next to this package's ``simulate`` (the dialect's entry).
COMMAND_LINE: Final = _CommandLine()
