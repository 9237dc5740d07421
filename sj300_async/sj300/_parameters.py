"""Parameter codes, the SJ300's function-code table and each parameter's scaling.

Commands 06 and 07 carry a parameter value as eight decimal digits. What
those digits mean depends on the parameter's resolution: F002 = 30.00 s is
sent as ``00003000`` (x 100), A004 = 50.0 Hz as ``00000500`` (x 10), C078 =
40 ms as ``00000040`` (x 1). :data:`PARAMETERS` lists every function code
of the SJ300's function list with its name, scale, unit, range and factory
value; for any other syntactically valid code the scale is x 10, as the
SJ300 appendix states, and raw integer access is always available. The
catalogue never refuses a code it lacks: drives differ by firmware, and the
drive is the judge (it answers NAK 16).

Where the table comes from (the seeds hold the communication appendix only,
which names a handful of codes; it has no function list):

- Codes and names of all six groups (F basic settings, A standard
  functions, B fine tuning, C intelligent terminals, H motor constants, P
  expansion cards): the function list of the Hitachi SJ300 instruction
  manual (chapter 3 and the parameter settings tables of its appendix C),
  written from knowledge of that manual, not from a copy in this
  repository. The D (monitor) and U (user-selected) codes are not in it:
  commands 06 / 07 address F, A, B, C, H and P only.
- The 41 codes the library catalogued before (F001..F004, A001..A004,
  A020, A038, A044, A061, A062, A082, A092, A093, B001, B012, B031, B084,
  B085, C001..C008, C070..C075, C078, H003, H004, H006, H203, H204) keep
  their entries unchanged: the seeds and tests pinned them.
- B100..B113 (free-setting V/f), the P group's DeviceNet codes P044..P049
  and the encoder codes P010..P032 exist on the manual's list but act only
  with the matching mode or expansion card; a drive whose firmware lacks a
  code answers NAK 16, and ``sj300 params backup`` records it as absent.

Decisions:

- Scale: the setting resolution the function list gives, so the raw value
  counts the parameter's smallest step (the reading that fits F002 = 3000
  for 30.00 s, as the SJ700 manual shows it): 0.01 -> x 100, 0.1 -> x 10,
  0.001 -> x 1000. Selections (the manual's 00 / 01 / 02 choices), counts,
  pulses, ms, whole volts, ohms and whole per cents -> x 1, as the old
  entries A001, C078, A082 and H004 had it. Frequencies set in whole Hz
  (A003 / A004 and their 2nd / 3rd motor copies, B015 / B017 / B019,
  B100..B112) -> x 10, as A003 / A004 always had and as the appendix's
  "value times ten" says. The reference's default x 10 also stays the
  scale of every code this table lacks (:func:`parameter_info`): no code
  of the table has an unknown resolution, so none carries it by default.
- Frequencies the manual shows as 0.00..99.99 / 100.0..400.0 are x 100
  (the drive keeps 0.01 Hz inside; the display drops a digit above 100).
- Signed parameters (A111 / A112 -400..400 Hz, A113 / A114 -100..100 %,
  P024 -2048..2048): the eight-digit field has no sign, and the reference
  does not say how a negative value travels, so the catalogue's range is
  the non-negative half. Raw access reads whatever the drive sends.
- Ranges that scale with the drive's rating (currents 0.2..2.0 x rated) are
  0..9999.9 A; terminal-function and signal selections are 0..255 (which
  function codes a firmware assigns is the drive's to judge).
- B034 counts in tens of hours (0..65535 = 0..655350 h): its unit is
  named in its name, "(10 h units)", scale x 1.
- ``default`` is the manual's factory setting in the parameter's unit; None
  where it depends on the drive (rated current, motor capacity, country,
  voltage class, factory calibration). The simulator's parameter table
  takes its codes and these defaults from here.

Decision (a contradiction in the seed): the appendix says command 01 needs
"A003 = 01". On the SJ300 (and the SJ700 / L300P manuals) A001 is the
frequency source (03 = RS-485) and A003 is the base frequency in Hz; the
"A003 = 01" is a misprint of "A001 = 03". The catalogue and the simulator
follow the drive: A001 = 03 makes serial the frequency source, A002 = 03 the
run-command source.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Final

from ..wire import LocalProtocolError

__all__ = [
    "DEFAULT_SCALE",
    "GROUPS",
    "PARAMETERS",
    "RAW_VALUE_MAX",
    "RAW_VALUE_MIN",
    "ParameterInfo",
    "motor_capacity_kw",
    "normalize_code",
    "parameter_info",
]

#: Scale used for codes the catalogue does not know (the SJ300 appendix: "value x 10").
DEFAULT_SCALE: Final = 10
#: The eight-digit value field holds 0..99999999.
RAW_VALUE_MIN: Final = 0
RAW_VALUE_MAX: Final = 99_999_999

_CODE_RE = re.compile(r"[FABCHP][0-9]{3}")


@dataclass(frozen=True, slots=True)
class ParameterInfo:
    """What the library knows about one parameter."""

    #: Upper-case code, e.g. ``"F002"``.
    code: str
    #: Human-readable name from the manual.
    name: str
    #: Raw value = engineering value x scale.
    scale: int
    #: Unit of the engineering value ("" for codes and counts).
    unit: str
    #: Lowest engineering value the drive accepts.
    minimum: float
    #: Highest engineering value the drive accepts.
    maximum: float
    #: The factory setting (engineering value), None where it depends on the drive.
    default: float | None = None

    def to_raw(self, value: float) -> int:
        """Scale an engineering value to the integer sent on the wire.

        Raises:
            LocalProtocolError: the value is outside ``minimum..maximum`` or
                not representable at this parameter's resolution.
        """
        if not self.minimum <= value <= self.maximum:
            raise LocalProtocolError(
                f"{self.code} ({self.name}) must be within {self.minimum:g}..{self.maximum:g}"
                f"{' ' + self.unit if self.unit else ''}, got {value!r}"
            )
        raw = round(value * self.scale)
        if abs(raw - value * self.scale) > 1e-6 * max(1.0, abs(value * self.scale)):
            raise LocalProtocolError(
                f"{self.code} has a resolution of {1 / self.scale:g}"
                f"{' ' + self.unit if self.unit else ''}: "
                f"{value!r} cannot be sent exactly"
            )
        return raw

    def from_raw(self, raw: int) -> float:
        """Convert the integer read from the wire to the engineering value."""
        return raw / self.scale


def _p(
    code: str,
    name: str,
    scale: int,
    unit: str,
    lo: float,
    hi: float,
    default: float | None = None,
) -> ParameterInfo:
    return ParameterInfo(code, name, scale, unit, lo, hi, default)


_ORDINAL: Final = {2: "2nd", 3: "3rd"}


def _motors(first: ParameterInfo, *motors: int) -> tuple[ParameterInfo, ...]:
    """*first* and its copies for the 2nd / 3rd motor (code + 200 / + 300), in that order."""
    copies = (
        replace(
            first,
            code=f"{first.code[0]}{int(first.code[1:]) + 100 * m:03d}",
            name=f"{first.name}, {_ORDINAL[m]} motor",
        )
        for m in motors
    )
    return (first, *copies)


def _sel(code: str, name: str, hi: int, default: int | None = 0, lo: int = 0) -> ParameterInfo:
    """A selection (the manual's 00 / 01 / 02 ... choices): x 1, no unit."""
    return _p(code, name, 1, "", lo, hi, default)


def _hz(code: str, name: str, hi: float = 400.0, default: float | None = 0.0) -> ParameterInfo:
    """A frequency set at 0.01 Hz: x 100."""
    return _p(code, name, 100, "Hz", 0.0, hi, default)


# -- F: basic settings -------------------------------------------------------------------
_F_GROUP: Final = (
    _p("F001", "output frequency setting", 100, "Hz", 0.0, 400.0, 0.0),
    *_motors(_p("F002", "acceleration time 1", 100, "s", 0.01, 3600.0, 30.0), 2, 3),
    *_motors(_p("F003", "deceleration time 1", 100, "s", 0.01, 3600.0, 30.0), 2, 3),
    _p("F004", "keypad run key direction", 1, "", 0, 1, 0),
)

# -- A: standard functions ---------------------------------------------------------------
_A_GROUP: Final = (
    _p("A001", "frequency source", 1, "", 0, 10, 1),
    _p("A002", "run command source", 1, "", 1, 5, 1),
    # A003 / A004 / A082: the factory value depends on B085 (50 or 60 Hz; 400 or 460 V).
    *_motors(_p("A003", "base frequency", 10, "Hz", 30.0, 400.0), 2, 3),
    *_motors(_p("A004", "maximum frequency", 10, "Hz", 30.0, 400.0), 2, 3),
    _sel("A005", "[AT] selection", 4),
    _sel("A006", "[O2] selection", 3),
    _hz("A011", "[O]-[L] input active range start frequency"),
    _hz("A012", "[O]-[L] input active range end frequency"),
    _p("A013", "[O]-[L] input active range start voltage", 1, "%", 0, 100, 0),
    _p("A014", "[O]-[L] input active range end voltage", 1, "%", 0, 100, 100),
    _sel("A015", "[O]-[L] input start frequency enable", 1, 1),
    _p("A016", "external frequency filter time constant", 1, "", 1, 30, 8),
    _sel("A019", "multi-speed operation selection", 1),
    *_motors(_hz("A020", "multi-speed frequency 0"), 2, 3),
    *(_hz(f"A0{20 + i}", f"multi-speed frequency {i}") for i in range(1, 16)),
    _p("A038", "jog frequency", 100, "Hz", 0.0, 9.99, 1.0),
    _sel("A039", "jog stop mode", 2),
    *_motors(_sel("A041", "torque boost method", 1), 2),
    *_motors(_p("A042", "manual torque boost value", 10, "%", 0.0, 20.0, 1.0), 2, 3),
    *_motors(_p("A043", "manual torque boost frequency", 10, "%", 0.0, 50.0, 5.0), 2, 3),
    _sel("A044", "V/f characteristic curve", 5),
    _sel("A244", "V/f characteristic curve, 2nd motor", 4),
    _sel("A344", "V/f characteristic curve, 3rd motor", 1),
    _p("A045", "V/f gain", 1, "%", 20, 100, 100),
    _sel("A051", "DC braking enable", 1),
    _hz("A052", "DC braking frequency", 60.0, 0.5),
    _p("A053", "DC braking wait time", 10, "s", 0.0, 5.0, 0.0),
    _p("A054", "DC braking force for deceleration", 1, "%", 0, 100, 0),
    _p("A055", "DC braking time for deceleration", 10, "s", 0.0, 60.0, 0.0),
    _sel("A056", "DC braking edge or level detection for [DB]", 1, 1),
    _p("A057", "DC braking force at start", 1, "%", 0, 100, 0),
    _p("A058", "DC braking time at start", 10, "s", 0.0, 60.0, 0.0),
    _p("A059", "DC braking carrier frequency", 10, "kHz", 0.5, 15.0, 3.0),
    *_motors(_hz("A061", "frequency upper limit"), 2),
    *_motors(_hz("A062", "frequency lower limit"), 2),
    _hz("A063", "jump frequency 1"),
    _hz("A064", "jump frequency width 1", 10.0, 0.5),
    _hz("A065", "jump frequency 2"),
    _hz("A066", "jump frequency width 2", 10.0, 0.5),
    _hz("A067", "jump frequency 3"),
    _hz("A068", "jump frequency width 3", 10.0, 0.5),
    _hz("A069", "acceleration pause frequency"),
    _p("A070", "acceleration pause time", 10, "s", 0.0, 60.0, 0.0),
    _sel("A071", "PID enable", 1),
    _p("A072", "PID proportional gain", 10, "", 0.2, 5.0, 1.0),
    _p("A073", "PID integral time constant", 10, "s", 0.0, 3600.0, 1.0),
    _p("A074", "PID derivative time constant", 100, "s", 0.0, 100.0, 0.0),
    _p("A075", "PV scale conversion", 100, "", 0.01, 99.99, 1.0),
    _sel("A076", "PV source", 3),
    _sel("A077", "reverse PID action", 1),
    _p("A078", "PID output limit", 10, "%", 0.0, 100.0, 0.0),
    _sel("A081", "AVR function select", 2),
    _p("A082", "AVR voltage", 1, "V", 200, 480),
    _sel("A085", "operation mode selection", 2),
    _p("A086", "energy saving mode tuning", 10, "%", 0.0, 100.0, 50.0),
    *_motors(_p("A092", "acceleration time 2", 100, "s", 0.01, 3600.0, 15.0), 2, 3),
    *_motors(_p("A093", "deceleration time 2", 100, "s", 0.01, 3600.0, 15.0), 2, 3),
    *_motors(_sel("A094", "select method to switch to acc2/dec2", 1), 2),
    *_motors(_hz("A095", "acc1 to acc2 frequency transition point"), 2),
    *_motors(_hz("A096", "dec1 to dec2 frequency transition point"), 2),
    _sel("A097", "acceleration curve selection", 3),
    _sel("A098", "deceleration curve selection", 3),
    _hz("A101", "[OI]-[L] input active range start frequency"),
    _hz("A102", "[OI]-[L] input active range end frequency"),
    _p("A103", "[OI]-[L] input active range start current", 1, "%", 0, 100, 20),
    _p("A104", "[OI]-[L] input active range end current", 1, "%", 0, 100, 100),
    _sel("A105", "[OI]-[L] input start frequency enable", 1, 1),
    # A111..A114 are signed on the drive (-400..400 Hz, -100..100 %): see the docstring.
    _hz("A111", "[O2]-[L] input active range start frequency"),
    _hz("A112", "[O2]-[L] input active range end frequency"),
    _p("A113", "[O2]-[L] input active range start voltage", 1, "%", 0, 100, None),
    _p("A114", "[O2]-[L] input active range end voltage", 1, "%", 0, 100, 100),
    _p("A131", "acceleration curve constant", 1, "", 1, 10, 2),
    _p("A132", "deceleration curve constant", 1, "", 1, 10, 2),
)

# -- B: fine tuning ----------------------------------------------------------------------
# Currents whose factory value is a multiple of the drive's rated current have no
# default here (None): the simulator's model gives them (see _parameters_table.py).
_AMPS: Final = 9999.9

_B_GROUP: Final = (
    _sel("B001", "restart mode selection", 3),
    _p("B002", "allowable under-voltage power failure time", 10, "s", 0.3, 1.0, 1.0),
    _p("B003", "retry wait time before motor restart", 10, "s", 0.3, 100.0, 1.0),
    _sel("B004", "instantaneous power failure / under-voltage alarm enable", 2),
    _sel("B005", "number of restarts on power failure / under-voltage", 1),
    _sel("B006", "phase loss detection enable", 1),
    _hz("B007", "restart frequency threshold"),
    *_motors(_p("B012", "electronic thermal level", 10, "A", 0.0, _AMPS), 2, 3),
    *_motors(_sel("B013", "electronic thermal characteristic", 2, 1), 2, 3),
    _p("B015", "free-setting electronic thermal frequency 1", 10, "Hz", 0.0, 400.0, 0.0),
    _p("B016", "free-setting electronic thermal current 1", 10, "A", 0.0, 1000.0, 0.0),
    _p("B017", "free-setting electronic thermal frequency 2", 10, "Hz", 0.0, 400.0, 0.0),
    _p("B018", "free-setting electronic thermal current 2", 10, "A", 0.0, 1000.0, 0.0),
    _p("B019", "free-setting electronic thermal frequency 3", 10, "Hz", 0.0, 400.0, 0.0),
    _p("B020", "free-setting electronic thermal current 3", 10, "A", 0.0, 1000.0, 0.0),
    _sel("B021", "overload restriction operation mode", 3, 1),
    _p("B022", "overload restriction level", 10, "A", 0.0, _AMPS),
    _p("B023", "deceleration rate at overload restriction", 100, "s", 0.1, 30.0, 1.0),
    _sel("B024", "overload restriction operation mode 2", 3, 1),
    _p("B025", "overload restriction level 2", 10, "A", 0.0, _AMPS),
    _p("B026", "deceleration rate at overload restriction 2", 100, "s", 0.1, 30.0, 1.0),
    _sel("B031", "software lock mode", 3, 1),
    _p("B034", "run/power-on warning time (10 h units)", 1, "", 0, 65535, 0),
    _sel("B035", "rotational direction restriction", 2),
    _p("B036", "reduced voltage start selection", 1, "", 0, 6, 6),
    _sel("B037", "function code display restriction", 2),
    _sel("B040", "torque limit selection", 4),
    _p("B041", "torque limit 1 (forward driving)", 1, "%", 0, 200, 150),
    _p("B042", "torque limit 2 (reverse regenerating)", 1, "%", 0, 200, 150),
    _p("B043", "torque limit 3 (reverse driving)", 1, "%", 0, 200, 150),
    _p("B044", "torque limit 4 (forward regenerating)", 1, "%", 0, 200, 150),
    _sel("B045", "torque limit LADSTOP enable", 1),
    _sel("B046", "reverse run protection enable", 1),
    _sel("B050", "controlled deceleration on power loss", 1),
    _p("B051", "DC bus voltage trigger level during power loss", 10, "V", 0.0, 1000.0),
    _p("B052", "over-voltage threshold during power loss", 10, "V", 0.0, 1000.0),
    _p("B053", "deceleration time during power loss", 100, "s", 0.01, 3600.0, 1.0),
    _hz("B054", "initial output frequency decrease during power loss", 10.0),
    _p("B080", "[AM] analog signal gain", 1, "", 0, 255, 180),
    _p("B081", "[FM] analog signal gain", 1, "", 0, 255, 60),
    _hz("B082", "start frequency adjustment", 9.99, 0.5),
    _p("B083", "carrier frequency", 10, "kHz", 0.5, 15.0, 5.0),
    _sel("B084", "initialization mode", 2),
    _p("B085", "country code for initialization", 1, "", 0, 2),
    _p("B086", "frequency scaling conversion factor", 10, "", 0.1, 99.9, 1.0),
    _sel("B087", "STOP key enable", 1),
    _sel("B088", "restart mode after FRS", 1),
    _p("B090", "dynamic braking usage ratio", 10, "%", 0.0, 100.0, 0.0),
    _sel("B091", "stop mode selection", 1),
    _sel("B092", "cooling fan control", 1),
    _sel("B095", "dynamic braking control", 2),
    _p("B096", "dynamic braking activation level", 1, "V", 330, 760),
    _sel("B098", "thermistor for thermal protection", 2),
    _p("B099", "thermal protection level", 1, "ohm", 0, 9999, 3000),
    *(
        p
        for i in range(1, 8)
        for p in (
            _p(f"B{98 + 2 * i:03d}", f"free-setting V/f frequency {i}", 10, "Hz", 0, 400, 0),
            _p(f"B{99 + 2 * i:03d}", f"free-setting V/f voltage {i}", 10, "V", 0, 800, 0),
        )
    ),
    _sel("B120", "brake control enable", 1),
    _p("B121", "brake wait time for release", 100, "s", 0.0, 5.0, 0.0),
    _p("B122", "brake wait time for acceleration", 100, "s", 0.0, 5.0, 0.0),
    _p("B123", "brake wait time for stopping", 100, "s", 0.0, 5.0, 0.0),
    _p("B124", "brake wait time for confirmation", 100, "s", 0.0, 5.0, 0.0),
    _hz("B125", "brake release frequency"),
    _p("B126", "brake release current", 10, "A", 0.0, _AMPS),
)

# -- C: intelligent terminal functions ---------------------------------------------------
# Factory terminal functions: [1] RS, [2] AT, [3] JG, [4] FRS, [5] 2CH, [6] CF2, [7] CF1,
# [8] RV; outputs [11] FA1, [12] RUN, [13] OL, [14] OTQ, [15] IP, alarm relay AL.
_INPUT_DEFAULTS: Final = (18, 16, 6, 11, 9, 3, 2, 1)
_OUTPUT_DEFAULTS: Final = (1, 0, 3, 7, 8)

_C_GROUP: Final = (
    *(
        _p(f"C00{i}", f"intelligent input {i} function", 1, "", 0, 255, d)
        for i, d in enumerate(_INPUT_DEFAULTS, 1)
    ),
    *(_sel(f"C01{i}", f"intelligent input {i} active state", 1) for i in range(1, 9)),
    _sel("C019", "[FW] terminal active state", 1),
    *(
        _p(f"C02{i}", f"intelligent output {10 + i} function", 1, "", 0, 255, d)
        for i, d in enumerate(_OUTPUT_DEFAULTS, 1)
    ),
    _p("C026", "alarm relay function", 1, "", 0, 255, 5),
    _sel("C027", "[FM] signal selection", 255),
    _sel("C028", "[AM] signal selection", 255),
    _sel("C029", "[AMI] signal selection", 255),
    *(_sel(f"C03{i}", f"intelligent output {10 + i} active state", 1) for i in range(1, 6)),
    _sel("C036", "alarm relay active state", 1, 1),
    _sel("C040", "overload signal output mode", 1, 1),
    _p("C041", "overload level", 10, "A", 0.0, _AMPS),
    _hz("C042", "frequency arrival for acceleration"),
    _hz("C043", "frequency arrival for deceleration"),
    _p("C044", "PID deviation level", 10, "%", 0.0, 100.0, 3.0),
    _hz("C045", "frequency arrival for acceleration 2"),
    _hz("C046", "frequency arrival for deceleration 2"),
    _p("C055", "over-torque level (forward driving)", 1, "%", 0, 200, 100),
    _p("C056", "over-torque level (reverse regenerating)", 1, "%", 0, 200, 100),
    _p("C057", "over-torque level (reverse driving)", 1, "%", 0, 200, 100),
    _p("C058", "over-torque level (forward regenerating)", 1, "%", 0, 200, 100),
    _p("C061", "electronic thermal warning level", 1, "%", 0, 100, 80),
    _sel("C062", "alarm code output", 2),
    _hz("C063", "zero speed detection level", 100.0),
    _sel("C070", "data command source", 5, 2, lo=2),
    _sel("C071", "communication speed", 6, 4, lo=2),
    _p("C072", "node address", 1, "", 1, 32, 1),
    _sel("C073", "data bits", 8, 7, lo=7),
    _sel("C074", "parity", 2),
    _sel("C075", "stop bits", 2, 1, lo=1),
    _p("C078", "communication wait time", 1, "ms", 0, 1000, 0),
    # Analog calibrations: factory-trimmed per drive, hence no default.
    _p("C081", "[O] input span calibration", 1, "", 0, 65535, None),
    _p("C082", "[OI] input span calibration", 1, "", 0, 65535, None),
    _p("C083", "[O2] input span calibration", 1, "", 0, 65535, None),
    _p("C085", "thermistor input tuning", 10, "", 0.0, 1000.0, None),
    _p("C086", "[AM] terminal offset tuning", 10, "V", 0.0, 10.0, 0.0),
    _p("C087", "[AMI] terminal meter tuning", 1, "", 0, 255, 80),
    _p("C088", "[AMI] terminal offset tuning", 10, "mA", 0.0, 20.0, None),
    _sel("C091", "debug mode enable", 1),
    _sel("C101", "up/down memory mode selection", 1),
    _sel("C102", "reset mode selection", 2),
    _sel("C103", "restart mode after reset", 1),
    _p("C111", "overload level 2", 10, "A", 0.0, _AMPS),
    _p("C121", "[O] input zero calibration", 1, "", 0, 65535, None),
    _p("C122", "[OI] input zero calibration", 1, "", 0, 65535, None),
    _p("C123", "[O2] input zero calibration", 1, "", 0, 65535, None),
)

# -- H: motor constants ------------------------------------------------------------------
# The motor constants' factory values depend on H003 (the motor's capacity): no default.
_H_GROUP: Final = (
    _sel("H001", "auto-tuning setting", 2),
    *_motors(_sel("H002", "motor data selection", 2), 2),
    _p("H003", "motor capacity (code)", 1, "", 0, 21),
    _p("H203", "2nd motor capacity (code)", 1, "", 0, 21),
    _p("H004", "motor poles", 1, "", 2, 8, 4),
    _p("H204", "2nd motor poles", 1, "", 2, 8, 4),
    *_motors(_p("H005", "motor speed constant", 1000, "", 0.001, 80.0, 1.59), 2),
    *_motors(_p("H006", "motor stabilization constant", 1, "", 0, 255, 100), 2, 3),
    *_motors(_p("H020", "motor constant R1", 1000, "ohm", 0.001, 65.535), 2),
    *_motors(_p("H021", "motor constant R2", 1000, "ohm", 0.001, 65.535), 2),
    *_motors(_p("H022", "motor constant L", 100, "mH", 0.01, 655.35), 2),
    *_motors(_p("H023", "motor constant Io", 100, "A", 0.01, 655.35), 2),
    *_motors(_p("H024", "motor constant J", 1000, "kg m2", 0.001, 9999.0), 2),
    *_motors(_p("H030", "auto-tuned motor constant R1", 1000, "ohm", 0.001, 65.535), 2),
    *_motors(_p("H031", "auto-tuned motor constant R2", 1000, "ohm", 0.001, 65.535), 2),
    *_motors(_p("H032", "auto-tuned motor constant L", 100, "mH", 0.01, 655.35), 2),
    *_motors(_p("H033", "auto-tuned motor constant Io", 100, "A", 0.01, 655.35), 2),
    *_motors(_p("H034", "auto-tuned motor constant J", 1000, "kg m2", 0.001, 9999.0), 2),
    *_motors(_p("H050", "PI proportional gain", 10, "%", 0.0, 1000.0, 100.0), 2),
    *_motors(_p("H051", "PI integral gain", 10, "%", 0.0, 1000.0, 100.0), 2),
    *_motors(_p("H052", "P proportional gain", 100, "", 0.01, 10.0, 1.0), 2),
    *_motors(_p("H060", "zero LV limit", 10, "%", 0.0, 100.0, 100.0), 2),
    _p("H070", "terminal selection PI proportional gain", 10, "%", 0.0, 1000.0, 100.0),
    _p("H071", "terminal selection PI integral gain", 10, "%", 0.0, 1000.0, 100.0),
    _p("H072", "terminal selection P proportional gain", 100, "", 0.0, 10.0, 1.0),
)

# -- P: expansion card functions ---------------------------------------------------------
_P_GROUP: Final = (
    _sel("P001", "operation on expansion card 1 error", 1),
    _sel("P002", "operation on expansion card 2 error", 1),
    _sel("P010", "feedback option enable", 1),
    _p("P011", "encoder pulses per revolution", 1, "", 128, 65000, 1024),
    _sel("P012", "control pulse setting", 3),
    _sel("P013", "pulse train input mode", 2),
    _p("P014", "home search stop position", 1, "", 0, 4095, 0),
    _hz("P015", "home search speed", 120.0, 5.0),
    _sel("P016", "home search direction", 1),
    _p("P017", "home search completion range", 1, "pulses", 0, 10000, 5),
    _p("P018", "home search completion delay", 100, "s", 0.0, 9.99, 0.0),
    _sel("P019", "electronic gear set position", 1),
    _p("P020", "electronic gear ratio numerator", 1, "", 1, 9999, 1),
    _p("P021", "electronic gear ratio denominator", 1, "", 1, 9999, 1),
    _p("P022", "feed-forward gain", 100, "", 0.0, 655.35, 0.0),
    _p("P023", "position loop gain", 100, "", 0.0, 100.0, 0.5),
    # Signed on the drive (-2048..2048): see the docstring.
    _p("P024", "position bias", 1, "pulses", 0, 2048, 0),
    _sel("P025", "temperature compensation thermistor enable", 1),
    _p("P026", "over-speed error detection level", 10, "%", 0.0, 150.0, 135.0),
    _hz("P027", "speed deviation error detection level", 120.0, 7.5),
    _p("P028", "motor gear ratio numerator", 1, "", 1, 9999, 1),
    _p("P029", "motor gear ratio denominator", 1, "", 1, 9999, 1),
    _sel("P031", "acceleration/deceleration time input selection", 2),
    _sel("P032", "positioning command input selection", 2),
    _p("P044", "DeviceNet communication watchdog timer", 100, "s", 0.0, 99.99, 1.0),
    _sel("P045", "action on communication error", 4, 1),
    _p("P046", "DeviceNet polled I/O output instance", 1, "", 20, 100, 21),
    _p("P047", "DeviceNet polled I/O input instance", 1, "", 70, 101, 71),
    _sel("P048", "action on DeviceNet idle mode", 4, 1),
    _p("P049", "motor poles for RPM display", 1, "", 0, 38, 0),
)

#: Each group's codes, in the order the manual's function list has them.
GROUPS: Final[dict[str, tuple[ParameterInfo, ...]]] = {
    "F": _F_GROUP,
    "A": _A_GROUP,
    "B": _B_GROUP,
    "C": _C_GROUP,
    "H": _H_GROUP,
    "P": _P_GROUP,
}

#: The SJ300's function-code table: every F, A, B, C, H and P code of the manual's
#: function list, in its order. A code outside it is still readable: see
#: :func:`parameter_info`.
PARAMETERS: Final[dict[str, ParameterInfo]] = {
    p.code: p for group in GROUPS.values() for p in group
}


def normalize_code(code: str | bytes) -> str:
    """Return *code* upper-cased after checking it is a parameter code.

    A code is a group letter F, A, B, C, H or P followed by three digits.
    Manuals print ``b084``; either case is accepted, upper case is sent.

    Raises:
        LocalProtocolError: *code* is not of that form.
    """
    if isinstance(code, bytes | bytearray):
        try:
            code = bytes(code).decode("ascii")
        except UnicodeDecodeError:
            raise LocalProtocolError(f"parameter code {code!r} is not ASCII") from None
    if not isinstance(code, str):
        raise LocalProtocolError(f"parameter code must be a str, got {type(code).__name__}")
    upper = code.upper()
    if not _CODE_RE.fullmatch(upper):
        raise LocalProtocolError(
            f"{code!r} is not a parameter code (a letter F/A/B/C/H/P and three digits)"
        )
    return upper


def parameter_info(code: str | bytes) -> ParameterInfo:
    """Return the catalogue entry for *code*, or a generic x 10 entry for a code it lacks.

    Raises:
        LocalProtocolError: *code* is not a syntactically valid parameter code.
    """
    upper = normalize_code(code)
    known = PARAMETERS.get(upper)
    if known is not None:
        return known
    return ParameterInfo(
        upper, "unknown parameter", DEFAULT_SCALE, "", RAW_VALUE_MIN / 10, RAW_VALUE_MAX / 10
    )


# H003 / H203 motor capacity codes -> kW. Index by code; None where the mode has no such code.
_CAPACITY_US: Final = (0.2, None, 0.4, None, 0.75, None, 1.5, 2.2, None, 3.7, None)
_CAPACITY_EU: Final = (0.2, 0.37, None, 0.55, 0.75, 1.1, 1.5, 2.2, 3.0, None, 4.0)
_CAPACITY_BOTH: Final = (5.5, 7.5, 11.0, 15.0, 18.5, 22.0, 30.0, 37.0, 45.0, 55.0, 75.0)


def motor_capacity_kw(code: int, country: int = 0) -> float | None:
    """Return the motor capacity in kW that an H003 / H203 code stands for.

    Args:
        code: the H003 / H203 value (0..21).
        country: B085; 01 selects the EU table, 00 and 02 the US table.

    Returns:
        The capacity, or ``None`` when the code means nothing in that mode.
    """
    if 0 <= code <= 10:
        table = _CAPACITY_EU if country == 1 else _CAPACITY_US
        return table[code]
    if 11 <= code <= 21:
        return _CAPACITY_BOTH[code - 11]
    return None
