"""The parameters a simulated FR-700 has: number, factory value, range, in link units.

The parameters of the codec's catalogue
(:data:`sj300_async.fr700.FR700_PARAMETERS`: name, unit, increment, range
and special settings, one source for both sides), with the FR-A700 factory
values of a 2.2K drive, as the raw integers the link carries (Pr.7 = 50
means 5.0 s); and a few the catalogue does not name (:data:`UNCATALOGUED`),
as a real drive has hundreds the library does not model: a backup keeps
them as raw integers. Their ranges are not modelled: any four-digit value
is taken. Numbers in neither table do not exist for the simulated drive
(a read or write answers NAK B).

The calibration parameters Pr.902..Pr.905 (terminal 2 and 4 frequency
setting bias and gain) are two values each, as the reference's
second-parameter switch (H6C / HEC) implies: the frequency (switch H00,
0.01 Hz) and the analog value (H01, 0.1 %, :data:`BIAS_GAIN_ANALOG`); a
read or write reaches the half the switch selects.

Decisions where the reference is silent: "9999" settings are the raw value
9999 (H270F), as the catalogue sends them; every parameter here may be
written while the drive runs, except Pr.79 (operation mode selection); Pr.77
(parameter write selection) = 1 refuses every parameter write but Pr.77's
own with NAK A (mode error: the write is not allowed now), as the manuals'
"write disabled"; a parameter clear (HFC) restores the factory values of
everything but the communication parameters (Pr.117..Pr.124, Pr.337,
Pr.340 and Pr.341), whichever of the four clear codes is sent.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from ...fr700.codec import FR700_PARAMETERS

__all__ = [
    "BIAS_GAIN_ANALOG",
    "COMMUNICATION",
    "PARAMETERS",
    "UNCATALOGUED",
    "WRITE_SELECTION",
    "ParameterSpec",
    "factory_values",
]

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
    77: 0,  # parameter write selection: written only while stopped (here: any time)
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

#: Parameters the catalogue does not name, with their FR-A700 factory values (raw).
UNCATALOGUED: Final[Mapping[int, int]] = MappingProxyType(
    {
        13: 50,  # starting frequency 0.50 Hz
        15: 500,  # jog frequency 5.00 Hz
        16: 5,  # jog acceleration/deceleration time 0.5 s
        18: 12000,  # high speed maximum frequency 120.00 Hz
        22: 1500,  # stall prevention operation level 150.0 %
        902: 0,  # terminal 2 frequency setting bias frequency 0.00 Hz (C2)
        903: 6000,  # terminal 2 frequency setting gain frequency 60.00 Hz
        904: 0,  # terminal 4 frequency setting bias frequency 0.00 Hz (C5)
        905: 6000,  # terminal 4 frequency setting gain frequency 60.00 Hz
    }
)

#: The analog halves of the bias/gain parameters (second-parameter switch H01), x 0.1 %.
BIAS_GAIN_ANALOG: Final[Mapping[int, int]] = MappingProxyType(
    {902: 0, 903: 1000, 904: 200, 905: 1000}  # C3, C4, C6, C7: 0 %, 100 %, 20 % (4 mA), 100 %
)
#: The highest analog value of a bias/gain parameter, x 0.1 % (300 %).
BIAS_GAIN_ANALOG_MAX: Final = 3000

#: Pr.77, the parameter write selection: 1 refuses every parameter write but its own.
WRITE_SELECTION: Final = 77

#: Parameters the drive refuses to write while it outputs.
_NOT_WHILE_RUNNING: Final = frozenset({79})

PARAMETERS: Final[Mapping[int, ParameterSpec]] = MappingProxyType(
    {
        **{
            number: ParameterSpec(
                number,
                _FACTORY[number],
                info.raw_minimum,
                info.raw_maximum,
                frozenset(info.special),
                number not in _NOT_WHILE_RUNNING,
            )
            for number, info in FR700_PARAMETERS.items()
        },
        **{number: ParameterSpec(number, raw, 0, 0xFFFF) for number, raw in UNCATALOGUED.items()},
    }
)

#: Parameters a parameter clear keeps: the communication settings.
COMMUNICATION: Final = frozenset({*range(117, 125), 337, 340, 341})


def factory_values() -> dict[int, int]:
    """A fresh copy of every parameter's factory value."""
    return {number: spec.factory for number, spec in PARAMETERS.items()}
