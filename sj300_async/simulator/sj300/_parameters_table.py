"""The simulated drive's parameter table: which codes it knows, their factory values and limits.

A simulated drive knows every code of the library's catalogue
(:data:`sj300_async.PARAMETERS`, the SJ300's whole function-code table):
the catalogue is the one list of codes, and this module adds none. Any other
code gets NAK 16, as a real drive answers for a code its firmware lacks.
Values are stored raw (the eight digits of commands 06 / 07); limits come
from the catalogue's range times its scale, so the drive and the host
library agree by construction.

Factory values: the catalogue's ``default`` (the manual's factory setting)
where it has one; else what this module's model says (below); else 0, or
the lowest raw value of the range when 0 is outside it.

Decisions (not in the seeds; the SJ300 manual's factory-setting tables and
common practice):

- The simulated model is a 5.5 kW, 400 V class drive (SJ300-055H): H003 =
  H203 = 11 (5.5 kW in both the US and the EU table), 12.0 A rated current
  (B012 / B212 / B312 electronic thermal level, C041 / C111 overload
  signal levels, B126 brake release current), 18.0 A overload restriction
  (B022 / B025, 1.5 x rated), the 400 V class voltages (B051 440 V, B052
  720 V, B096 720 V) and A082 = 400 V (460 V for the US).
- B085 country code: 00 Japan, 01 Europe, 02 USA. It selects the base and
  maximum frequency (A003 / A004 and the 2nd / 3rd motor's A203 / A204 /
  A303 / A304: 50 Hz in Europe, 60 Hz elsewhere) and the AVR voltage. The
  simulator's default country is Europe.
- True factory defaults take the run command and frequency from the
  terminals (A001 = A002 = 01), so a serial 00 / 01 is refused with NAK 13.
  :data:`SERIAL_CONTROL` is the small change an integrator makes first, and
  what a simulated drive starts with unless asked for factory defaults.
- C001..C008 carry the SJ300's factory terminal functions (RS, AT, JG, FRS,
  2CH, CF2, CF1, RV). A function code is the bit number of that function in
  command 02, which is how the monitor block shows terminals set by 02, and
  why C001..C008 accept only the function codes command 02 can carry.
- Command 08 keeps B085 (it is the input of the initialization) and the
  line settings C071..C075: the simulated line is fixed by the server, and
  a drive whose readback disagreed with the line it answers on would only
  mislead.
- The codes the model does not use (most of them) are stored and read
  back, checked against their range only.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import Final

from ...sj300.codec import PARAMETERS, InputTerminal, motor_capacity_kw
from .._pacing import LinePacing

__all__ = [
    "KEPT_BY_INITIALIZATION",
    "SERIAL_CONTROL",
    "Country",
    "factory_table",
    "line_parameters",
    "value_error",
]


class Country(enum.IntEnum):
    """B085: the country whose factory values command 08 loads."""

    JAPAN = 0  #: 60 Hz, US motor capacity table
    EUROPE = 1  #: 50 Hz, EU motor capacity table
    USA = 2  #: 60 Hz, US motor capacity table


#: A001 / A002 value selecting the RS-485 port as frequency / run-command source.
SOURCE_SERIAL: Final = 3
#: A002 value selecting the FW / RV terminals as run-command source.
SOURCE_TERMINAL: Final = 1

#: What an integrator changes first so the serial line runs the drive.
SERIAL_CONTROL: Final[dict[str, int]] = {"A001": SOURCE_SERIAL, "A002": SOURCE_SERIAL}

#: Parameters command 08 leaves alone (see the module docstring).
KEPT_BY_INITIALIZATION: Final = ("B085", "C071", "C072", "C073", "C074", "C075")

# Raw values (the eight digits on the wire) the simulated model gives, same for every country.
_RATED_DECIAMPS: Final = 120  # 12.0 A
_MODEL: Final[dict[str, int]] = {
    "B012": _RATED_DECIAMPS,
    "B212": _RATED_DECIAMPS,
    "B312": _RATED_DECIAMPS,
    "B022": _RATED_DECIAMPS * 3 // 2,
    "B025": _RATED_DECIAMPS * 3 // 2,
    "B126": _RATED_DECIAMPS,
    "C041": _RATED_DECIAMPS,
    "C111": _RATED_DECIAMPS,
    "B051": 4400,  # 440.0 V
    "B052": 7200,  # 720.0 V
    "B096": 720,  # V
    "H003": 11,  # 5.5 kW
    "H203": 11,
}

_BY_COUNTRY: Final[dict[Country, dict[str, int]]] = {
    country: dict.fromkeys(("A003", "A203", "A303", "A004", "A204", "A304"), hz) | {"A082": volts}
    for country, hz, volts in (
        (Country.JAPAN, 600, 400),
        (Country.EUROPE, 500, 400),
        (Country.USA, 600, 460),
    )
}


def _catalogue_range(code: str) -> tuple[int, int]:
    info = PARAMETERS[code]
    return round(info.minimum * info.scale), round(info.maximum * info.scale)


def _catalogue_factory(code: str) -> int:
    """The catalogue's default (raw), else 0 within the range."""
    info = PARAMETERS[code]
    if info.default is not None:
        return info.to_raw(info.default)
    low, high = _catalogue_range(code)
    return min(max(0, low), high)


#: Every catalogued code's factory value, before the model and the country.
_CATALOGUE: Final[dict[str, int]] = {code: _catalogue_factory(code) for code in PARAMETERS}

# C001..C008: their range is the set of function codes command 02 can carry
# (FW, bit 0, has a terminal of its own).
_TERMINAL_FUNCTIONS: Final = frozenset(t.bit_length() - 1 for t in InputTerminal) - {0}
_TERMINAL_CODES: Final = frozenset(f"C00{i}" for i in range(1, 9))


def factory_table(country: Country, node: int) -> dict[str, int]:
    """Return the factory values (raw) of a drive at *node* for *country*."""
    table = _CATALOGUE | _MODEL | _BY_COUNTRY[country]
    table["B085"] = int(country)
    table["C072"] = node
    return table


# C071 codes of the speeds an SJ300 offers.
_SPEED_CODES: Final = {2400: 3, 4800: 4, 9600: 5, 19200: 6}
_PARITY_CODES: Final = {"N": 0, "E": 1, "O": 2}


def line_parameters(line: LinePacing) -> dict[str, int]:
    """C071 / C073..C075 for *line* (C071 only when the SJ300 offers that speed)."""
    settings = {
        "C073": line.bytesize,
        "C074": _PARITY_CODES[line.parity],
        "C075": line.stopbits,
    }
    speed = _SPEED_CODES.get(line.baudrate)
    if speed is not None:
        settings["C071"] = speed
    return settings


def value_error(code: str, raw: int, table: Mapping[str, int]) -> str | None:
    """Why the drive refuses *raw* for *code* given the rest of *table*, or None if it accepts.

    *code* must be one the drive knows (a key of *table*).
    """
    if code in _TERMINAL_CODES:
        return None if raw in _TERMINAL_FUNCTIONS else "not an input terminal function"
    low, high = _catalogue_range(code)
    if not low <= raw <= high:
        return f"outside {low}..{high}"
    # A real drive keeps its frequencies consistent: base <= maximum, setpoint <= maximum.
    if code == "A003" and raw > table["A004"]:
        return "base frequency above maximum frequency A004"
    if code == "A004" and raw < table["A003"]:
        return "maximum frequency below base frequency A003"
    if code == "F001" and raw > table["A004"] * 10:
        return "above maximum frequency A004"
    if code in ("H003", "H203") and motor_capacity_kw(raw, table["B085"]) is None:
        return "no motor capacity for this code in the B085 country table"
    if code == "C072" and raw != table["C072"]:
        # The simulated bus routes by the node a drive was created at.
        return "re-addressing a simulated drive is not supported"
    return None
