"""The SJ300 as the gateway and the command line see it: its profile.

What its answers mean in neutral terms, its parameters, its register
block, and what its drives can do (every trip history, intelligent input
terminals, a broadcast stop).

Decisions:

- *Running* is status B's "running" (the output is on), the gateway's
  register 200 and MQTT's ``running`` since the first release.
- The state in words is status A, with status C telling how a running
  drive's output moves (``accelerating``, ``reversing``); status A 02, "on
  stopping" in the manual, is the stopped state (its output is off), and
  a drive ramping down to a stop (status A 02 with C "decelerating") is
  ``stopping``. A code the manual does not list reads ``state 42``.
- The set frequency is F001 (the output frequency setting): polling it
  reads the setpoint, and a frequency command is confirmed by reading it back.
- The register block is the one docs/GATEWAY.md prints since the gateway's
  first release (104..112 the monitor's other items, 202..204 status A/B/C,
  300.. the trip count and the six trip records).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from math import isfinite
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
    in_counts,
    words,
)
from ..wire import BadFrame, LocalProtocolError
from ._codes import NakCode, StatusA, StatusB, StatusC, TripCode
from ._constants import BROADCAST, MAX_NODE, MIN_NODE
from ._drive import Drive
from ._parameters import (
    PARAMETERS,
    RAW_VALUE_MAX,
    RAW_VALUE_MIN,
    normalize_code,
    parameter_info,
)
from ._payloads import InverterStatus, MonitorData, TripHistory, TripRecord
from ._request_parser import RequestParser
from ._requests import Request
from ._terminals import InputTerminal

__all__ = [
    "SJ300_PROFILE",
    "Sj300Extras",
    "Sj300Profile",
    "describe_request_frame",
    "sj300_state",
]


@dataclass(frozen=True, slots=True)
class Sj300Extras:
    """What only an SJ300 snapshot holds: the drive class's own results, as read."""

    status: InverterStatus | None = None
    monitor: MonitorData | None = None
    trip_history: TripHistory | None = None


#: Status A as a person says it; RUNNING is told apart by status C (:data:`_MOVING`).
_STATES: Final[dict[StatusA, str]] = {
    StatusA.INITIAL: "starting up",
    StatusA.STOPPING: "stopped",  # "on stopping": the output is off
    StatusA.FREE_RUN_STOP: "coasting",
    StatusA.JOGGING: "jogging",
    StatusA.DYNAMIC_BRAKING: "braking",
    StatusA.RETRY: "retrying",
    StatusA.TRIP: "tripped",
    StatusA.UNDER_VOLTAGE: "under-voltage",
}
#: What a running drive's output does, by status C (anything else: "running").
_MOVING: Final[dict[StatusC, str]] = {
    StatusC.ACCELERATING: "accelerating",
    StatusC.DECELERATING: "decelerating",
    StatusC.FORWARD_START: "starting",
    StatusC.REVERSE_START: "starting",
    StatusC.REVERSE_FROM_FORWARD: "reversing",
    StatusC.FORWARD_FROM_REVERSE: "reversing",
}


#: Every word :func:`sj300_state` gives for a known status (the profile's ``states``).
SJ300_STATES: Final = tuple(
    sorted({*_STATES.values(), *_MOVING.values(), "running", "stopping", "tripped"})
)


def sj300_state(status: InverterStatus) -> str:
    """The drive's state in a word or two (see the module docstring)."""
    if status.tripped:
        return "tripped"
    if status.a == StatusA.RUNNING:
        return _MOVING.get(status.c, "running")
    if status.a == StatusA.STOPPING and status.c == StatusC.DECELERATING:
        return "stopping"  # ramping down to a stop
    return _STATES.get(status.a) or f"state {int(status.a)}"


class _Catalogue:
    """The SJ300 function-code table as a :class:`~sj300_async.profiles.ParameterCatalogue`."""

    def code(self, text: str) -> str | None:
        try:
            return normalize_code(text)
        except LocalProtocolError:
            return None

    def spec(self, code: str) -> ParameterSpec:
        return parameter_info(code)

    def codes(self) -> Sequence[str]:
        return tuple(PARAMETERS)

    def addressable(self) -> Sequence[str]:
        # The table names every code a drive can have; firmware lacking one answers NAK 16.
        return tuple(PARAMETERS)

    @property
    def raw_range(self) -> tuple[int, int]:
        return RAW_VALUE_MIN, RAW_VALUE_MAX


#: What a refusal usually means, by command and NAK code.
_HINTS: Final[dict[tuple[str, int], str]] = {
    ("run", NakCode.EXECUTION_DISABLED): "the run command source A002 must be 03 (serial)",
    ("frequency", NakCode.EXECUTION_DISABLED): "the frequency source A001 must be 03 (serial)",
    ("frequency", NakCode.ABNORMAL_PARAMETER): "above the maximum frequency A004?",
}


def describe_request_frame(frame: bytes) -> str:
    """A frame the host wrote, read back as a drive reads it: node, command, name, data."""
    parts = []
    for event in RequestParser().feed(frame):
        if isinstance(event, Request):
            who = "broadcast" if event.node == BROADCAST else f"node {event.node:02d}"
            name = event.command.name.lower().replace("_", " ")
            text = f"{who} command {event.command.wire.decode()} {name}"
            parts.append(f"{text} {event.data.decode('ascii', 'replace')}" if event.data else text)
        elif isinstance(event, BadFrame):
            parts.append(f"bad request: {event.reason.value}")
        else:
            parts.append(f"discarded {len(event.data)} byte(s): {event.reason.value}")
    return "; ".join(parts) or frame_text(frame)


# -- the register block ---------------------------------------------------------------------


def _extras(snapshot: DriveSnapshot) -> Sj300Extras | None:
    extras = snapshot.extras
    return extras if isinstance(extras, Sj300Extras) else None


# The monitor's and the status's readers run at every Modbus read of a unit (a SCADA
# reads thousands a second at plant scale): _extras and in_counts are inlined.


def _monitor(
    get: Callable[[MonitorData], float], per_unit: float = 1
) -> Callable[[DriveSnapshot], int | None]:
    def read(snapshot: DriveSnapshot) -> int | None:
        extras = snapshot.extras
        if not isinstance(extras, Sj300Extras) or extras.monitor is None:
            return None
        value = get(extras.monitor)
        return round(value * per_unit) if isfinite(value) else None

    return read


def _status(get: Callable[[InverterStatus], int]) -> Callable[[DriveSnapshot], int | None]:
    def read(snapshot: DriveSnapshot) -> int | None:
        extras = snapshot.extras
        if not isinstance(extras, Sj300Extras) or extras.status is None:
            return None
        return get(extras.status)

    return read


def _trip_record(
    index: int, get: Callable[[TripRecord], float], per_unit: float = 1
) -> Callable[[DriveSnapshot], int | None]:
    def read(snapshot: DriveSnapshot) -> int | None:
        extras = _extras(snapshot)
        history = None if extras is None else extras.trip_history
        if history is None or index >= len(history.records):
            return None
        return in_counts(get(history.records[index]), per_unit)

    return read


def _trip_count(snapshot: DriveSnapshot) -> int | None:
    extras = _extras(snapshot)
    history = None if extras is None else extras.trip_history
    return None if history is None else history.total_count


def _register_fields() -> tuple[RegisterField, ...]:
    m: ReadGroup = "monitor"
    s: ReadGroup = "status"
    t: ReadGroup = "trips"
    fields = [
        RegisterField(104, "output torque", "1 %", _monitor(lambda x: x.output_torque_percent),
                      m, signed=True),
        RegisterField(105, "power", "0.1 kW", _monitor(lambda x: x.power_kw, 10), m),
        RegisterField(106, "PID feedback", "0.01 %",
                      _monitor(lambda x: x.pid_feedback_percent, 100), m),
        RegisterField(107, "input terminals", "bit field",
                      _monitor(lambda x: int(x.input_terminals)), m),
        RegisterField(108, "output terminals", "bit field",
                      _monitor(lambda x: int(x.output_terminals)), m),
        RegisterField(109, "frequency x conversion factor (B086)", "0.01",
                      _monitor(lambda x: x.frequency_conversion, 100), m),
        RegisterField(110, "run time", "1 h", _monitor(lambda x: x.run_time_h), m, width=2),
        RegisterField(112, "power-on time", "1 h", _monitor(lambda x: x.power_on_time_h), m,
                      width=2),
        RegisterField(202, "status A (operating state)", "code", _status(lambda x: int(x.a)), s),
        RegisterField(203, "status B (0 stopped, 1 running, 2 tripped)", "code",
                      _status(lambda x: int(x.b)), s),
        RegisterField(204, "status C (what the output does)", "code",
                      _status(lambda x: int(x.c)), s),
        RegisterField(300, "trip count", "1", _trip_count, t, width=2),
    ]  # fmt: skip
    for i in range(6):
        base = 302 + 10 * i
        rec = f"trip {i + 1} (newest first):"
        fields += [
            RegisterField(base, f"{rec} E-code number (0: empty)", "code",
                          _trip_record(i, lambda r: r.trip_factor), t),
            RegisterField(base + 1, f"{rec} status A", "code",
                          _trip_record(i, lambda r: int(r.status_a)), t),
            RegisterField(base + 2, f"{rec} output frequency", "0.01 Hz",
                          _trip_record(i, lambda r: r.output_frequency_hz, 100), t),
            RegisterField(base + 3, f"{rec} output current", "0.1 A",
                          _trip_record(i, lambda r: r.output_current_a, 10), t),
            RegisterField(base + 4, f"{rec} output voltage", "0.1 V",
                          _trip_record(i, lambda r: r.output_voltage_v, 10), t),
            RegisterField(base + 5, f"{rec} run time", "1 h",
                          _trip_record(i, lambda r: r.run_time_h), t, width=2),
            RegisterField(base + 7, f"{rec} power-on time", "1 h",
                          _trip_record(i, lambda r: r.power_on_time_h), t, width=2),
            RegisterField(base + 9, f"{rec} status C", "code",
                          _trip_record(i, lambda r: int(r.status_c)), t),
        ]  # fmt: skip
    return tuple(fields)


# -- the profile ----------------------------------------------------------------------------


class Sj300Profile:
    """The SJ300's :class:`~sj300_async.profiles.Profile` (see the module docstring)."""

    name = "sj300"
    model = "SJ300"
    manufacturer = "Hitachi"
    node_noun = "node"
    node_range = (MIN_NODE, MAX_NODE)
    capabilities = Capabilities(
        trip_history=True,
        terminals=True,
        broadcast_stop=True,
        store=True,
        parameter_backup=True,
        measures=frozenset({"output_torque_percent", "power_kw"}),
        states=SJ300_STATES,
    )
    unit_offset = 0
    max_frequency_hz = 400.0
    max_frequency_parameter: str | None = "A004"
    setpoint_parameter: str | None = "F001"
    ramp_parameters = ("F002", "F003")
    address_parameter: str | None = "C072"
    line_parameters = ("C071", "C073", "C074", "C075")
    kept_parameters: tuple[str, ...] = ()
    last_parameters: tuple[str, ...] = ()

    def __init__(self) -> None:
        self.parameters = _Catalogue()
        self.registers = RegisterLayout(
            protocol_id=1,
            fields=_register_fields(),
            parameter_bases={"F": 10000, "A": 12000, "B": 14000, "C": 16000, "H": 18000,
                             "P": 20000},
        )  # fmt: skip

    def __repr__(self) -> str:
        return "SJ300_PROFILE"

    def status_view(self, status: InverterStatus) -> StatusView:
        return StatusView(
            running=status.b == StatusB.RUNNING,
            tripped=status.tripped,
            state=sj300_state(status),
            fields={"a": status.a.name, "b": status.b.name, "c": status.c.name},
        )

    def monitor_view(self, monitor: MonitorData) -> MonitorView:
        return MonitorView(
            output_frequency_hz=monitor.output_frequency_hz,
            output_current_a=monitor.output_current_a,
            output_voltage_v=monitor.output_voltage_v,
            direction=monitor.direction,
            output_torque_percent=float(monitor.output_torque_percent),
            power_kw=monitor.power_kw,
        )

    def trip(self, number: int) -> Trip:
        code = TripCode(number)
        return Trip(code.error_code, int(code), code.name, code.description)

    def trip_log(self, history: TripHistory) -> TripLog:
        return TripLog(history.total_count, tuple(self._record(r) for r in history.trips))

    def _record(self, record: TripRecord) -> Trip:
        named = self.trip(record.trip_factor)
        return Trip(
            named.code,
            named.number,
            named.name,
            named.meaning,
            output_frequency_hz=record.output_frequency_hz,
            output_current_a=record.output_current_a,
            output_voltage_v=record.output_voltage_v,
            run_time_h=record.run_time_h,
            power_on_time_h=record.power_on_time_h,
            details=(
                ("state", words(record.status_a)),
                ("output", words(record.status_c)),
                ("causes", words(record.status_b)),
            ),
            record=record,
        )

    def extras(
        self,
        status: InverterStatus | None,
        monitor: MonitorData | None,
        trips: TripHistory | None,
    ) -> Sj300Extras:
        return Sj300Extras(status, monitor, trips)

    async def read_set_frequency(self, drive: Drive) -> float:
        return float(await drive.read_parameter("F001"))

    async def read_trips(self, drive: Drive) -> TripHistory:
        return await drive.read_trip_history()

    async def read_latest_trip(self, drive: Drive) -> Trip | None:
        # A trip while tripped is not recorded: the newest record is the present trip.
        trips = (await drive.read_trip_history()).trips
        return self._record(trips[0]) if trips else None

    async def reset(self, drive: Drive) -> None:
        # The RS input through command 02, then every command-02 input off (an input
        # held through command 02, such as FW, is released too).
        await drive.set_terminals(InputTerminal.RS)
        await drive.set_terminals(0)

    def status_rows(self, status: InverterStatus, monitor: MonitorData) -> list[tuple[str, str]]:
        m = monitor
        return [
            ("state", sj300_state(status)),
            ("state (A)", _coded(status.a)),
            ("run (B)", _coded(status.b)),
            ("output (C)", _coded(status.c)),
            ("output frequency", f"{m.output_frequency_hz:.2f} Hz"),
            ("direction", words(m.direction)),
            ("output current", f"{m.output_current_a:.1f} A"),
            ("output voltage", f"{m.output_voltage_v:.1f} V"),
            ("output torque", f"{m.output_torque_percent} %"),
            ("power", f"{m.power_kw:.1f} kW"),
            ("PID feedback", f"{m.pid_feedback_percent:.2f} %"),
            ("frequency conversion", f"{m.frequency_conversion:.2f}"),
            ("input terminals", words(m.input_terminals)),
            ("output terminals", words(m.output_terminals)),
            ("run time", f"{m.run_time_h} h"),
            ("power-on time", f"{m.power_on_time_h} h"),
        ]

    def trip_codes(self) -> Sequence[Trip]:
        return tuple(self.trip(code) for code in TripCode)

    def nak_hint(self, code: int, command: str) -> str | None:
        return _HINTS.get((command, code))

    def absent(self, code: int) -> bool:
        # NAK 16: a code the drive's firmware lacks (drives differ by firmware).
        return code == NakCode.ABNORMAL_PARAMETER

    def request_describer(self, dialect: Any) -> Callable[[bytes], str]:
        return describe_request_frame


SJ300_PROFILE: Final = Sj300Profile()


def _coded(member: StatusA | StatusB | StatusC) -> str:
    """A status code in words and as the manual numbers it: ``stopped (02)``.

    Status A 02, "on stopping" in the manual, is the stopped state (module
    docstring): worded ``stopped``, as the state row and the monitor say.
    """
    word = "stopped" if member is StatusA.STOPPING else words(member)
    return f"{word} ({int(member):02d})"
