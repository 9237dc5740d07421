"""The FR-700 parameter catalogue: name, unit, setting increment and range of each parameter.

The link carries a parameter as a raw integer 0..65535 (four hex digits)
counted in the parameter's setting increment: Pr.7 (acceleration time,
0.1 s increments) = 50 means 5.0 s, Pr.1 (maximum frequency, 0.01 Hz) =
12000 means 120.00 Hz. :meth:`Fr700ParameterInfo.from_raw` and
:meth:`~Fr700ParameterInfo.to_raw` convert between that integer and the
value in the parameter's unit, which
:meth:`~sj300_async.fr700.Fr700Drive.read_parameter` and
:meth:`~sj300_async.fr700.Fr700Drive.write_parameter` use;
``read_parameter_raw`` / ``write_parameter_raw`` move the integer itself.

Sources: the parameters the protocol reference and the seed name
(Pr.117..Pr.124, Pr.337, Pr.340, Pr.341, Pr.1) and those the simulator
models, with the setting ranges and increments of the FR-A700 parameter
list (55K and smaller). The simulator (:mod:`sj300_async.simulator.fr700`)
takes its ranges from this table, so the two cannot disagree.

Decisions where the reference is silent:

- A number the catalogue does not list is **refused** by the unit methods
  (:func:`fr700_parameter_info` raises :class:`LocalProtocolError` naming
  ``read_parameter_raw`` / ``write_parameter_raw``; nothing is sent). The
  FR-700 has several hundred parameters whose increments are 1, 0.1, 0.01
  or 0.001 of different units; guessing a scale of 1 for an unknown one
  would read Pr.44 (second acceleration time, 0.1 s) as 50 instead of
  5.0 s, and writing 5.0 would set 0.5 s: a silent factor of ten in a ramp
  time or a frequency is worse than a clear error. The raw methods take
  any number 0..999 and let the drive judge (NAK B for one it lacks).
- Special settings ("8888", "9999": not used, no function, ...) are sent as
  the raw integer 8888 / 9999 (H22B8 / H270F, the simulator's convention)
  whatever the increment, and read back as the number the manual and the
  operation panel show: Pr.122 raw 9999 reads 9999.0 ("no communication
  check"), not 999.9 s. Writing 9999 sets it. A value in the unit whose raw
  integer would collide with a special setting (Pr.19 = 888.8 V or 999.9
  V at 0.1 V) is refused: it would read back as the special setting.
- Pr.7 and Pr.8 are counted in 0.1 s, which holds while Pr.21
  (acceleration/deceleration time increments) is 0, the factory setting.
  A drive with Pr.21 = 1 counts them in 0.01 s (0..360 s): use the raw
  methods there.
- Ranges are the setting ranges of the parameter list; drives check some
  values against others (a frequency above Pr.1 ...) and answer NAK C:
  the catalogue only refuses what no drive would accept.

Validation happens before anything reaches the wire: a value outside the
range, finer than the increment, or not a real number raises
:class:`LocalProtocolError` (a :class:`ValueError`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Final

from ..wire import LocalProtocolError
from ._requests import parameter_bank

__all__ = [
    "FR700_PARAMETERS",
    "PARAMETER_RAW_MAX",
    "Fr700ParameterInfo",
    "fr700_parameter_info",
    "parameter_number",
]

#: The four hex digits of a parameter's data hold 0..65535.
PARAMETER_RAW_MAX: Final = 0xFFFF

#: "Not used" / "no function": the setting 9999 many parameters have.
_NOT_USED: Final = 9999

_EMPTY: Final[Mapping[int, str]] = MappingProxyType({})


@dataclass(frozen=True, slots=True)
class Fr700ParameterInfo:
    """What the library knows about one FR-700 parameter.

    ``raw = value / increment``: Pr.7 (increment 0.1 s) = 5.0 s travels as 50.
    """

    #: Parameter number 0..999 (``Pr.7`` is 7).
    number: int
    #: Name from the parameter list.
    name: str
    #: Unit of the value ("" for selections and counts).
    unit: str
    #: Decimal places of the setting increment: 0 (1), 1 (0.1) or 2 (0.01).
    decimals: int
    #: Lowest value in the unit (special settings aside).
    minimum: float
    #: Highest value in the unit (special settings aside).
    maximum: float
    #: Special settings, as the raw integer (= the number the manual shows), and their meaning.
    special: Mapping[int, str] = field(default_factory=lambda: _EMPTY, hash=False)

    @property
    def default(self) -> float | None:
        """None: the reference this catalogue follows lists no factory settings (many
        depend on the drive's capacity), so none is claimed."""
        return None

    @property
    def scale(self) -> int:
        """Raw counts per unit: 1, 10 or 100."""
        return int(10**self.decimals)

    @property
    def increment(self) -> float:
        """The setting increment in the unit (0.1 for Pr.7)."""
        return 1 / self.scale

    @property
    def raw_minimum(self) -> int:
        """The raw integer of :attr:`minimum`."""
        return round(self.minimum * self.scale)

    @property
    def raw_maximum(self) -> int:
        """The raw integer of :attr:`maximum`."""
        return round(self.maximum * self.scale)

    @property
    def code(self) -> str:
        """``"Pr.7"``: the number as the gateway, the command line and MQTT name it."""
        return f"Pr.{self.number}"

    @property
    def label(self) -> str:
        """``"Pr.7 acceleration time"``: the number and name, for messages."""
        return f"Pr.{self.number} {self.name}"

    def accepts_raw(self, raw: int) -> bool:
        """True when *raw* is in range or one of the special settings."""
        return self.raw_minimum <= raw <= self.raw_maximum or raw in self.special

    def from_raw(self, raw: int) -> float:
        """The value in the unit of the raw integer read from the drive.

        A special setting reads as itself (Pr.122 raw 9999 is 9999.0).
        """
        if raw in self.special:
            return float(raw)
        return raw / self.scale

    def to_raw(self, value: float) -> int:
        """The raw integer to send for *value* in the unit.

        Raises:
            LocalProtocolError: not a real number, outside ``minimum..maximum``
                (and not a special setting), finer than the increment, or
                colliding with a special setting's raw integer.
        """
        if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
            raise LocalProtocolError(f"{self.label} needs a number, got {value!r}")
        if value in self.special:  # 9999 and 9999.0 alike
            return round(value)
        unit = f" {self.unit}" if self.unit else ""
        if not self.minimum <= value <= self.maximum:
            specials = "".join(f", or {s} ({meaning})" for s, meaning in self.special.items())
            raise LocalProtocolError(
                f"{self.label} must be within {self.minimum:g}..{self.maximum:g}{unit}"
                f"{specials}, got {value!r}"
            )
        exact = value * self.scale
        raw = round(exact)
        # tolerate float noise (139.47 * 100 = 13946.999999999998), not a finer value
        if abs(raw - exact) > 1e-9 * max(1.0, abs(exact)):
            raise LocalProtocolError(
                f"{self.label} is set in steps of {self.increment:g}{unit}: "
                f"{value!r} cannot be sent exactly"
            )
        if raw in self.special:
            raise LocalProtocolError(
                f"{self.label} = {value!r}{unit} would be sent as {raw}, "
                f"which the drive reads as the special setting {raw} ({self.special[raw]})"
            )
        return raw


def _p(
    number: int,
    name: str,
    unit: str,
    decimals: int,
    lo: float,
    hi: float,
    special: Mapping[int, str] = _EMPTY,
) -> Fr700ParameterInfo:
    return Fr700ParameterInfo(number, name, unit, decimals, lo, hi, MappingProxyType(dict(special)))


_NO_FUNCTION: Final = {_NOT_USED: "not used"}

#: The catalogue, by parameter number. Not exhaustive: see :func:`fr700_parameter_info`.
FR700_PARAMETERS: Final[Mapping[int, Fr700ParameterInfo]] = MappingProxyType(
    {
        p.number: p
        for p in (
            _p(0, "torque boost", "%", 1, 0.0, 30.0),
            _p(1, "maximum frequency", "Hz", 2, 0.0, 120.0),
            _p(2, "minimum frequency", "Hz", 2, 0.0, 120.0),
            _p(3, "base frequency", "Hz", 2, 0.0, 400.0),
            _p(4, "multi-speed setting (high speed)", "Hz", 2, 0.0, 400.0),
            _p(5, "multi-speed setting (middle speed)", "Hz", 2, 0.0, 400.0),
            _p(6, "multi-speed setting (low speed)", "Hz", 2, 0.0, 400.0),
            _p(7, "acceleration time", "s", 1, 0.0, 3600.0),
            _p(8, "deceleration time", "s", 1, 0.0, 3600.0),
            _p(9, "electronic thermal O/L relay", "A", 2, 0.0, 500.0),
            _p(
                19,
                "base frequency voltage",
                "V",
                1,
                0.0,
                1000.0,
                {8888: "95% of the power supply voltage", _NOT_USED: "power supply voltage"},
            ),
            _p(20, "acceleration/deceleration reference frequency", "Hz", 2, 1.0, 400.0),
            _p(41, "up-to-frequency sensitivity", "%", 1, 0.0, 100.0),
            _p(42, "output frequency detection", "Hz", 2, 0.0, 400.0),
            _p(77, "parameter write selection", "", 0, 0, 2),
            _p(79, "operation mode selection", "", 0, 0, 7),
            _p(117, "PU communication station number", "", 0, 0, 31),
            _p(118, "PU communication speed (x 100 bps)", "", 0, 48, 1152),
            _p(119, "PU communication stop bit length / data length", "", 0, 0, 11),
            _p(120, "PU communication parity check", "", 0, 0, 2),
            _p(121, "number of PU communication retries", "", 0, 0, 10, _NO_FUNCTION),
            _p(
                122,
                "PU communication check time interval",
                "s",
                1,
                0.0,
                999.8,
                {_NOT_USED: "no communication check"},
            ),
            _p(
                123,
                "PU communication waiting time setting",
                "ms",
                0,
                0,
                150,
                {_NOT_USED: "set by the waiting-time field of each request"},
            ),
            _p(124, "PU communication CR/LF selection", "", 0, 0, 2),
            _p(
                337,
                "RS-485 communication waiting time setting",
                "ms",
                0,
                0,
                150,
                {_NOT_USED: "set by the waiting-time field of each request"},
            ),
            _p(340, "communication startup mode selection", "", 0, 0, 10),
            _p(341, "RS-485 communication CR/LF selection", "", 0, 0, 2),
        )
    }
)


def parameter_number(number: int | str) -> int:
    """The parameter number 0..999 of ``7``, ``"7"``, ``"Pr.7"`` or ``"pr 7"``.

    Raises:
        LocalProtocolError: not a parameter number 0..999.
    """
    bank, offset = parameter_bank(number)
    return bank * 100 + offset


def fr700_parameter_info(number: int | str) -> Fr700ParameterInfo:
    """The catalogue entry of parameter *number* (``7`` or ``"Pr.7"``).

    Raises:
        LocalProtocolError: not a parameter number 0..999, or one the catalogue
            does not list (its message names the raw methods, which take any number).
    """
    n = parameter_number(number)
    info = FR700_PARAMETERS.get(n)
    if info is None:
        raise LocalProtocolError(
            f"Pr.{n} is not in the FR-700 parameter catalogue, so its unit and increment "
            "are unknown: use read_parameter_raw / write_parameter_raw for the raw integer"
        )
    return info
