"""The parameters a simulated FR-700 has: number, factory value, range, in link units.

The parameters of the codec's catalogue
(:data:`sj300_async.fr700.FR700_PARAMETERS`: name, unit, increment, range
and special settings, one source for both sides), with the FR-A700 factory
values of a 2.2K drive, as the raw integers the link carries (Pr.7 = 50
means 5.0 s). Numbers not in the table do not exist for the simulated
drive (a read or write answers NAK B).

Decisions where the reference is silent: "9999" settings are the raw value
9999 (H270F), as the catalogue sends them; every parameter here may be
written while the drive runs, except Pr.79 (operation mode selection); a
parameter clear (HFC) restores the factory values of everything but the
communication parameters (Pr.117..Pr.124, Pr.337, Pr.340 and Pr.341),
whichever of the four clear codes is sent.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from ...fr700.codec import FR700_PARAMETERS

__all__ = ["COMMUNICATION", "PARAMETERS", "ParameterSpec", "factory_values"]

#: "Not used" / "no function" setting of many parameters.
NOT_USED: Final = 9999


@dataclass(frozen=True, slots=True)
class ParameterSpec:
    """One parameter: factory value and range in link units."""

    number: int
    factory: int
    low: int
    high: int
    #: Also accepted outside low..high (9999 = not used).
    extra: frozenset[int] = frozenset()
    #: May be written while the inverter outputs.
    while_running: bool = True

    def accepts(self, raw: int) -> bool:
        """True when the drive takes *raw* for this parameter."""
        return self.low <= raw <= self.high or raw in self.extra


#: Factory values (raw) of a 2.2K FR-A700, for every parameter of the catalogue.
_FACTORY: Final[Mapping[int, int]] = {
    0: 30,  # torque boost 3.0 %
    1: 12000,  # maximum frequency 120.00 Hz
    2: 0,
    3: 6000,  # base frequency 60.00 Hz
    4: 6000,
    5: 3000,
    6: 1000,
    7: 50,  # acceleration time 5.0 s
    8: 50,
    9: 960,  # electronic thermal O/L relay: rated current 9.60 A
    19: NOT_USED,
    20: 6000,
    41: 100,  # up-to-frequency sensitivity 10.0 %
    42: 600,  # output frequency detection 6.00 Hz
    79: 0,
    117: 0,
    118: 192,  # 19200 bps
    119: 1,
    120: 2,
    121: 1,
    122: NOT_USED,
    123: NOT_USED,
    124: 1,
    337: NOT_USED,
    340: 0,
    341: 1,
}

#: Parameters the drive refuses to write while it outputs.
_NOT_WHILE_RUNNING: Final = frozenset({79})

PARAMETERS: Final[Mapping[int, ParameterSpec]] = MappingProxyType(
    {
        number: ParameterSpec(
            number,
            _FACTORY[number],
            info.raw_minimum,
            info.raw_maximum,
            frozenset(info.special),
            number not in _NOT_WHILE_RUNNING,
        )
        for number, info in FR700_PARAMETERS.items()
    }
)

#: Parameters a parameter clear keeps: the communication settings.
COMMUNICATION: Final = frozenset({*range(117, 125), 337, 340, 341})


def factory_values() -> dict[int, int]:
    """A fresh copy of every parameter's factory value."""
    return {number: spec.factory for number, spec in PARAMETERS.items()}
