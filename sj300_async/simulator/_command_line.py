"""What a protocol's simulator offers ``sj300 simulate``: its own options and how to build its line.

``sj300 simulate`` knows no protocol: it finds a protocol's simulator
through the dialect (``Dialect.simulator``, ``"module:callable"``) and, in
that module, a ``COMMAND_LINE`` attribute (:class:`SimulateCommandLine`) that
declares the options only that protocol's simulated line takes (an argument
group of their own: ``--country`` for SJ300, ``--terminator`` for FR-700),
builds the simulated line from the parsed options, words its mode for the
summary line and names a simulated drive's latest trip. A protocol whose
simulator module has none cannot be served by ``sj300 simulate`` (its
``sim://`` bus still works).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from ._pacing import LinePacing

__all__ = [
    "SimulateCommandLine",
    "SimulateOption",
    "SimulateSettings",
]


@dataclass(frozen=True, slots=True)
class SimulateOption:
    """One option of a protocol's simulated line, as ``sj300 simulate`` takes it."""

    #: ``"--country"``.
    flag: str
    #: Where the parsed value goes (the key of :attr:`SimulateSettings.options`).
    dest: str
    help: str
    #: The values it takes (empty: a switch, or any text).
    choices: tuple[str, ...] = ()
    default: str | None = None
    #: A switch (``store_true``), not a value.
    switch: bool = False


@dataclass(frozen=True, slots=True)
class SimulateSettings:
    """What ``sj300 simulate`` asks of the simulated line."""

    nodes: tuple[int, ...]
    factory_defaults: bool
    #: The drives' own wait before replying in ms (None: their default).
    wait_ms: int | None
    #: The line's settings when given (``--baud`` and friends), else None.
    line: LinePacing | None
    #: The protocol's own options, by :attr:`SimulateOption.dest`.
    options: Mapping[str, Any] = field(default_factory=dict)


class SimulateCommandLine(Protocol):
    """A protocol's part of ``sj300 simulate`` (see the module docstring)."""

    #: The title of its options' argument group.
    title: str
    options: tuple[SimulateOption, ...]

    def build(self, settings: SimulateSettings) -> Any:
        """The simulated line (a ``BusModel`` with ``drives``).

        Raises:
            LocalProtocolError: an option the drives refuse.
        """

    def describe(self, bus: Any, settings: SimulateSettings) -> str:
        """Its mode in a few words, for the summary line (``serial control``)."""

    def trip_name(self, drive: Any) -> str:
        """A simulated drive's latest trip as the drive shows it (``E07``, ``E.OC1``)."""
