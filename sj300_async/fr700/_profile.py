"""The FR-700 as the gateway and the command line see it: its profile.

Decisions:

- *Running* is the status monitor's RUN bit; the direction comes from the
  status too (the FR-700's monitor reads carry none): stop when RUN is
  clear, else reverse when the REV bit is set, else forward.
- The state in words: ``tripped`` (ABC1, or H79's fault bit), ``running``,
  ``running reverse``, ``stopped``.
- Parameters are the catalogued ones (``Pr.7``), whose unit and increment
  are known; the set frequency has a read of its own (H6D), so no polled
  parameter stands for it. The maximum frequency is Pr.1.
- Unit ids are station + 100 (station 0 exists, and unit 0 is Modbus's
  broadcast), so that an SJ300 line's and an FR-700 line's defaults never
  collide in one gateway.
- The trip history is the fault history (H74..H77, four reads): the last
  eight faults, newest first, named as the display shows them (``E.OC1``)
  with their meaning from the reference's table; the drive counts no
  trips (the trip count is unknown). A code the table does not list is
  named by its byte (``fault HE9``). Its registers: 301 the trips
  recorded (0..8), 302..309 each one's fault code, newest first.
- No intelligent terminals over the link, no broadcast (the computer link
  has no broadcast station).
- A parameter backup (``sj300 params``) walks every number the link can
  address, Pr.0..Pr.999 (:meth:`_Catalogue.addressable`: banks 0..9 of the
  link-parameter extension, 100 offsets each), not the catalogue, which
  names only the parameters the library models: a drive has several
  hundred, and a model or firmware lacks some numbers. A number the drive
  refuses with NAK B (no such instruction code: the offset addresses
  nothing in that bank) is absent; any other refusal of a read is an
  error. An uncatalogued parameter is kept as its raw integer.
- What a restore leaves alone: the station number Pr.117 (the address) and,
  unless asked, the line settings of both ports, the PU connector's
  Pr.118..Pr.124 and the RS-485 terminals' Pr.332..Pr.337 and Pr.341, and
  the protocol selection Pr.549 (Modbus RTU would end the computer link):
  a new value cuts the drive off the line the tool talks on. Never: the
  RS-485 terminals' station number Pr.331 (another address of the drive),
  the communication error count Pr.343 (read-only), and the calibration
  parameters Pr.900..Pr.999 (the C-codes of the operation panel: meter and
  analog-input calibration). A calibration is the drive's own hardware
  measured, so another drive's would spoil it; and each bias/gain
  parameter is two values behind the second-parameter switch (H6C/HEC), of
  which a backup reads the one the switch selects (H00, the frequency,
  unless a program changed it). A backup records them, so ``params diff``
  shows a changed one.
- Pr.77 (parameter write selection) is written last: 1 refuses every
  parameter write but its own (NAK A), so a file taken from a write-locked
  drive must set it after the others; a drive locked now refuses the
  writes before it, which the restore tries again once Pr.77 is written.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final

from ..profiles import (
    Capabilities,
    DriveSnapshot,
    MonitorView,
    ParameterSpec,
    ReadGroup,
    RegisterField,
    RegisterLayout,
    StatusView,
    Trip,
    TripLog,
    frame_text,
    words,
)
from ..wire import Direction
from ._codec import MAX_STATION, MIN_STATION
from ._codes import Fr700Instruction, Fr700NakCode, Fr700StatusBits
from ._dialect import FR700_DIALECT, Fr700Dialect
from ._drive import Fr700Drive
from ._faults import FAULT_HISTORY_DEPTH, Fr700Fault, Fr700FaultHistory, known_fault_codes
from ._parameters import FR700_PARAMETERS, PARAMETER_RAW_MAX, fr700_parameter_info
from ._payloads import Fr700Monitor, Fr700Status
from ._request_parser import BadRequest, HostAnswer, HostRequest, RequestParser
from ._requests import MAX_PARAMETER

__all__ = ["FR700_PROFILE", "Fr700Extras", "Fr700Profile", "fr700_state"]


@dataclass(frozen=True, slots=True)
class Fr700Extras:
    """What only an FR-700 snapshot holds: the status monitor as read."""

    status: Fr700Status | None = None


#: Every word :func:`fr700_state` gives (the profile's ``states``).
FR700_STATES: Final = ("running", "running reverse", "stopped", "tripped")


def fr700_state(status: Fr700Status) -> str:
    """The drive's state in a word or two (see the module docstring)."""
    if status.tripped:
        return "tripped"
    if status.running:
        return "running reverse" if status.reverse else "running"
    return "stopped"


def _direction(status: Fr700Status) -> Direction:
    if Fr700StatusBits.RUN not in status.bits:
        return Direction.STOP
    return Direction.REVERSE if status.reverse else Direction.FORWARD


class _Catalogue:
    """The FR-700 parameter catalogue as a :class:`~sj300_async.profiles.ParameterCatalogue`."""

    def code(self, text: str) -> str | None:
        return FR700_DIALECT.parameter_code(text)

    def spec(self, code: str) -> ParameterSpec:
        return fr700_parameter_info(code)

    def codes(self) -> Sequence[str]:
        return tuple(f"Pr.{number}" for number in sorted(FR700_PARAMETERS))

    def addressable(self) -> Sequence[str]:
        return _ADDRESSABLE

    @property
    def raw_range(self) -> tuple[int, int]:
        return 0, PARAMETER_RAW_MAX


#: Every parameter number the link-parameter extension reaches, in order.
_ADDRESSABLE: Final = tuple(f"Pr.{number}" for number in range(MAX_PARAMETER + 1))
#: The calibration parameters (C-codes): the 900s.
_CALIBRATION: Final = tuple(f"Pr.{number}" for number in range(900, MAX_PARAMETER + 1))

_MODE_HINT: Final = (
    "the drive must be in network (computer link) operation mode (Pr.79, or HFB H0000), "
    "and stopped for some writes"
)
#: What a refusal usually means, by command and NAK code.
_HINTS: Final[dict[tuple[str, int], str]] = {
    ("run", Fr700NakCode.MODE): _MODE_HINT,
    ("frequency", Fr700NakCode.MODE): _MODE_HINT,
    ("frequency", Fr700NakCode.DATA_RANGE): "above the maximum frequency Pr.1?",
    ("restore", Fr700NakCode.MODE): _MODE_HINT + "; Pr.77 = 1 refuses every write but Pr.77",
}


def request_describer(dialect: Fr700Dialect) -> Callable[[bytes], str]:
    """What reads a frame the host wrote back in words, with *dialect*'s line options."""
    wait_field = dialect.options.wait_field
    terminator = dialect.options.terminator

    def describe(frame: bytes) -> str:
        parts = []
        for event in RequestParser(wait_field=wait_field, terminator=terminator).feed(frame):
            if isinstance(event, HostRequest):
                code = event.instruction
                text = f"station {event.station:02d} instruction H{code:02X} {_instruction(code)}"
                data = event.data.decode("ascii", "replace")
                parts.append(f"{text} {data}" if event.data else text)
            elif isinstance(event, HostAnswer):
                answer = "NAK: send the data again" if event.reoutput else "ACK: data received"
                parts.append(f"station {event.station:02d} host {answer}")
            elif isinstance(event, BadRequest):
                parts.append(f"bad request: {event.code.description}")
            else:
                parts.append(f"discarded {len(event.data)} byte(s): {event.reason.value}")
        # Without a terminator a frame ends by its length: the parser may want more.
        return "; ".join(parts) or frame_text(frame)

    return describe


def _instruction(code: int) -> str:
    """An FR-700 instruction's name; the parameter ranges by their first code's."""
    try:
        name = Fr700Instruction(code).name
    except ValueError:
        if code <= 0x63:  # H00..H63: parameter offsets
            name = Fr700Instruction.READ_PARAMETER.name
        elif 0x74 <= code <= 0x77:
            name = Fr700Instruction.FAULT_HISTORY.name
        elif 0x80 <= code <= 0xE3:
            name = Fr700Instruction.WRITE_PARAMETER.name
        else:
            return "(unnamed)"
    return name.lower().replace("_", " ")


def _trip_fields() -> tuple[RegisterField, ...]:
    """301 the trips recorded, 302.. each one's fault code, newest first (0: empty)."""
    t: ReadGroup = "trips"

    def recorded(snapshot: DriveSnapshot) -> int | None:
        return None if snapshot.trips is None else len(snapshot.trips.records)

    def code(index: int) -> Callable[[DriveSnapshot], int | None]:
        def read(snapshot: DriveSnapshot) -> int | None:
            if snapshot.trips is None:
                return None
            records = snapshot.trips.records
            return records[index].number if index < len(records) else 0

        return read

    name = "trip {} (newest first): fault code (0: empty)"
    return (
        RegisterField(301, "trips recorded (0..8)", "1", recorded, t),
        *(
            RegisterField(302 + i, name.format(i + 1), "code", code(i), t)
            for i in range(FAULT_HISTORY_DEPTH)
        ),
    )


def _status_bits(snapshot: DriveSnapshot) -> int | None:
    extras = snapshot.extras
    status = extras.status if isinstance(extras, Fr700Extras) else None
    return None if status is None else int(status.bits)


class Fr700Profile:
    """The FR-700's :class:`~sj300_async.profiles.Profile` (see the module docstring)."""

    name = "fr700"
    model = "FR-700"
    manufacturer = "Mitsubishi Electric"
    node_noun = "station"
    node_range = (MIN_STATION, MAX_STATION)
    capabilities = Capabilities(trip_history=True, parameter_backup=True, states=FR700_STATES)
    unit_offset = 100
    max_frequency_hz = 400.0
    max_frequency_parameter: str | None = "Pr.1"
    setpoint_parameter: str | None = None
    ramp_parameters = ("Pr.7", "Pr.8")
    address_parameter: str | None = "Pr.117"
    line_parameters = (
        *(f"Pr.{number}" for number in range(118, 125)),  # the PU connector
        *(f"Pr.{number}" for number in range(332, 338)),  # the RS-485 terminals
        "Pr.341",
        "Pr.549",  # protocol selection
    )
    kept_parameters = ("Pr.331", "Pr.343", *_CALIBRATION)
    # Written after the rest, in this order: the settings that change how the drive
    # takes the link's writes. Pr.342 (EEPROM or RAM only), the command and start-up
    # sources (Pr.338..340, Pr.550, Pr.551) and the operation mode Pr.79 (a mode
    # other than NET refuses later writes with NAK A), then the write lock Pr.77
    # (1 refuses every write but its own). From the manual as remembered: the
    # reference describes none of them; a review asked for them last.
    last_parameters = (
        "Pr.342",
        "Pr.338",
        "Pr.339",
        "Pr.340",
        "Pr.550",
        "Pr.551",
        "Pr.79",
        "Pr.77",
    )

    def __init__(self) -> None:
        self.parameters = _Catalogue()
        self.registers = RegisterLayout(
            protocol_id=2,
            fields=(
                RegisterField(202, "status bits (H7A/H79)", "bit field", _status_bits, "status"),
                *_trip_fields(),
            ),
            parameter_bases={"Pr.": 30000},
        )

    def __repr__(self) -> str:
        return "FR700_PROFILE"

    def status_view(self, status: Fr700Status) -> StatusView:
        return StatusView(
            running=status.running,
            tripped=status.tripped,
            state=fr700_state(status),
            direction=_direction(status),
            fields={"bits": int(status.bits)},
        )

    def monitor_view(self, monitor: Fr700Monitor) -> MonitorView:
        return MonitorView(
            output_frequency_hz=monitor.output_frequency_hz,
            output_current_a=monitor.output_current_a,
            output_voltage_v=monitor.output_voltage_v,
        )

    def trip(self, number: int) -> Trip:
        fault = Fr700Fault.of(number)
        if fault.meaning is None:  # not in the table: its byte
            return Trip(f"H{number:02X}", number, None, None)
        return Trip(fault.display, number, fault.display.removeprefix("E."), fault.meaning)

    def trip_log(self, history: Fr700FaultHistory) -> TripLog:
        return TripLog(None, tuple(self.trip(fault.code) for fault in history.faults))

    def extras(self, status: Fr700Status | None, monitor: Any, trips: Any) -> Fr700Extras:
        return Fr700Extras(status)

    async def read_set_frequency(self, drive: Fr700Drive) -> float:
        return float(await drive.read_set_frequency())

    async def read_trips(self, drive: Fr700Drive) -> Fr700FaultHistory:
        return await drive.read_fault_history()

    async def read_latest_trip(self, drive: Fr700Drive) -> Trip | None:
        # H74's low byte is the most recent fault (00: none).
        latest = await drive.read(Fr700Instruction.FAULT_HISTORY) & 0xFF
        return self.trip(latest) if latest else None

    async def reset(self, drive: Fr700Drive) -> None:
        # HFD H9696: the inverter reset. The drive sends no reply and restarts.
        await drive.reset()

    def status_rows(self, status: Fr700Status, monitor: Fr700Monitor) -> list[tuple[str, str]]:
        return [
            ("state", fr700_state(status)),
            ("status bits", words(status.bits)),
            ("output frequency", f"{monitor.output_frequency_hz:.2f} Hz"),
            ("direction", words(_direction(status))),
            ("output current", f"{monitor.output_current_a:.2f} A"),
            ("output voltage", f"{monitor.output_voltage_v:.1f} V"),
        ]

    def trip_codes(self) -> Sequence[Trip]:
        return tuple(self.trip(code) for code in known_fault_codes())

    def nak_hint(self, code: int, command: str) -> str | None:
        return _HINTS.get((command, code))

    def absent(self, code: int) -> bool:
        # NAK B: no such instruction code (a parameter this model lacks).
        return code == Fr700NakCode.INSTRUCTION_CODE

    def request_describer(self, dialect: Fr700Dialect) -> Callable[[bytes], str]:
        return request_describer(dialect)


FR700_PROFILE: Final = Fr700Profile()
