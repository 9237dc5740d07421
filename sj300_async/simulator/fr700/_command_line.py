"""The FR-700 simulator's part of ``sj300 simulate``: the line options, and its summary.

By default the drives' factory line settings: the waiting-time field
expected and every frame ending with CR (``--no-wait-field`` and
``--terminator none|cr|crlf`` change them, as Pr.123 and Pr.124 would).
"""

from __future__ import annotations

from typing import Final

from ...fr700.codec import Fr700Fault
from .._command_line import SimulateOption, SimulateSettings
from ._bus import Fr700SimulatedBus
from ._drive import Fr700SimulatedDrive

__all__ = ["COMMAND_LINE"]

_TERMINATORS: Final = {"none": "", "cr": "\r", "crlf": "\r\n"}


class _CommandLine:
    title = "FR-700 line (with --protocol fr700)"
    options = (
        SimulateOption(
            "--no-wait-field",
            "no_wait_field",
            "requests carry no waiting-time character (Pr.123 != 9999)",
            switch=True,
        ),
        SimulateOption(
            "--terminator",
            "terminator",
            "what ends every frame (Pr.124; default cr)",
            choices=tuple(sorted(_TERMINATORS)),
            default="cr",
        ),
    )

    def build(self, settings: SimulateSettings) -> Fr700SimulatedBus:
        options = settings.options
        bus = Fr700SimulatedBus(
            settings.nodes,
            wait_field=not options.get("no_wait_field", False),
            terminator=_TERMINATORS[str(options.get("terminator") or "cr")],
            factory_defaults=settings.factory_defaults,
        )
        if settings.wait_ms is not None:
            for drive in bus.drives.values():
                drive.set_wait_ms(settings.wait_ms)
        return bus

    def describe(self, bus: Fr700SimulatedBus, settings: SimulateSettings) -> str:
        mode = "FR-700, " + ("external mode" if settings.factory_defaults else "network mode")
        mode += f", terminator {settings.options.get('terminator') or 'cr'}"
        return mode + ("" if bus.wait_field else ", no waiting-time field")

    def trip_name(self, drive: Fr700SimulatedDrive) -> str:
        return Fr700Fault.of(drive.fault_history[0]).display


#: Found by ``sj300 simulate`` next to this package's ``simulate`` (the dialect's entry).
COMMAND_LINE: Final = _CommandLine()
