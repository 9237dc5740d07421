"""The parameters a simulated FR-700 has: number, factory value, range, in link units.

A small table of the parameters a host typically touches, with the FR-A700
factory values of a 2.2K drive, as the raw integers the link carries
(Pr.7 = 50 means 5.0 s). Numbers not in the table do not exist for the
simulated drive (a read or write answers NAK B).

Decisions where the reference is silent: "9999" settings are the raw value
9999 (H270F); every parameter here may be written while the drive runs,
except Pr.79 (operation mode selection); a parameter clear (HFC) restores
the factory values of everything but the communication parameters
(Pr.117..Pr.124 and Pr.340), whichever of the four clear codes is sent.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

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


def _p(
    number: int, factory: int, low: int, high: int, *extra: int, while_running: bool = True
) -> ParameterSpec:
    return ParameterSpec(number, factory, low, high, frozenset(extra), while_running)


PARAMETERS: Final[Mapping[int, ParameterSpec]] = MappingProxyType(
    {
        spec.number: spec
        for spec in (
            _p(0, 30, 0, 300),  # torque boost, x 0.1 %
            _p(1, 12000, 0, 12000),  # maximum frequency, x 0.01 Hz
            _p(2, 0, 0, 12000),  # minimum frequency
            _p(3, 6000, 0, 40000),  # base frequency
            _p(4, 6000, 0, 40000),  # multi-speed high
            _p(5, 3000, 0, 40000),  # multi-speed middle
            _p(6, 1000, 0, 40000),  # multi-speed low
            _p(7, 50, 0, 36000),  # acceleration time, x 0.1 s
            _p(8, 50, 0, 36000),  # deceleration time, x 0.1 s
            _p(9, 960, 0, 50000),  # electronic thermal O/L relay (rated current), x 0.01 A
            _p(19, NOT_USED, 0, 1000, 8888, NOT_USED),  # base frequency voltage, x 0.1 V
            _p(20, 6000, 100, 40000),  # acceleration/deceleration reference frequency
            _p(41, 100, 0, 1000),  # up-to-frequency sensitivity, x 0.1 %
            _p(42, 600, 0, 40000),  # output frequency detection (FU), x 0.01 Hz
            _p(79, 0, 0, 7, while_running=False),  # operation mode selection
            _p(117, 0, 0, 31),  # PU communication station number
            _p(118, 192, 48, 1152),  # communication speed, x 100 bps
            _p(119, 1, 0, 11),  # stop bit / data length
            _p(120, 2, 0, 2),  # parity check
            _p(121, 1, 0, 10, NOT_USED),  # number of retries
            _p(122, NOT_USED, 0, 9998, NOT_USED),  # communication check time, x 0.1 s
            _p(123, NOT_USED, 0, 150, NOT_USED),  # waiting time setting, ms
            _p(124, 1, 0, 2),  # CR/LF selection
            _p(340, 0, 0, 10),  # communication startup mode selection
        )
    }
)

#: Parameters a parameter clear keeps: the communication settings.
COMMUNICATION: Final = frozenset({*range(117, 125), 340})


def factory_values() -> dict[int, int]:
    """A fresh copy of every parameter's factory value."""
    return {number: spec.factory for number, spec in PARAMETERS.items()}
