"""The toy protocol's profile: what its answers mean to the gateway and the command line.

Registered through the dialect (``ToyDialect.profile``), like its simulator:
the gateway serves toy units over Modbus and MQTT with no library file
touched. A toy unit's status is a number (0 stopped, anything else its
speed: running), its monitor the speed, read as the output frequency in Hz;
it reports no current or voltage (None, never a made-up 0). Its parameters
are ``toy:KEY`` registers counted in whole units; its own register block is
the raw status at 500.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final

from sj300_async.profiles import (
    Capabilities,
    DriveSnapshot,
    MonitorView,
    ParameterSpec,
    RegisterField,
    RegisterLayout,
    StatusView,
    Trip,
    TripLog,
)
from sj300_async.wire import LocalProtocolError

from ._protocol import ToyDrive


@dataclass(frozen=True, slots=True)
class ToyParameter:
    """A toy register: whole units, 0..99999."""

    code: str
    name: str = "toy register"
    unit: str = ""
    scale: int = 1
    minimum: float = 0
    maximum: float = 99_999
    #: A toy has no factory settings.
    default: float | None = None

    def to_raw(self, value: float) -> int:
        if not self.minimum <= value <= self.maximum or value != int(value):
            raise LocalProtocolError(f"{self.code} is a whole number 0..99999, got {value!r}")
        return int(value)

    def from_raw(self, raw: int) -> float:
        return float(raw)


class _Catalogue:
    def code(self, text: str) -> str | None:
        return text if text.startswith("toy:") and len(text) > 4 else None

    def spec(self, code: str) -> ParameterSpec:
        if self.code(code) is None:
            raise LocalProtocolError(f"{code!r} is not a toy register (toy:KEY)")
        return ToyParameter(code)

    def codes(self) -> Sequence[str]:
        return ("toy:set", "toy:speed", "toy:status")

    def addressable(self) -> Sequence[str]:
        return self.codes()

    @property
    def raw_range(self) -> tuple[int, int]:
        return 0, 99_999


@dataclass(frozen=True, slots=True)
class ToyExtras:
    status: int | None


def _raw_status(snapshot: DriveSnapshot) -> int | None:
    extras = snapshot.extras
    return extras.status if isinstance(extras, ToyExtras) else None


class ToyProfile:
    name = "toy"
    model = "Toy unit"
    manufacturer = "the tests"
    node_noun = "unit"
    node_range = (1, 9)
    capabilities = Capabilities()
    unit_offset = 200
    max_frequency_hz = 500.0
    max_frequency_parameter: str | None = None
    setpoint_parameter: str | None = "toy:set"
    ramp_parameters = ("toy:ramp_up", "toy:ramp_down")
    address_parameter: str | None = None
    line_parameters: tuple[str, ...] = ()
    kept_parameters: tuple[str, ...] = ()
    last_parameters: tuple[str, ...] = ()

    def __init__(self) -> None:
        self.parameters = _Catalogue()
        self.registers = RegisterLayout(
            protocol_id=99,
            fields=(RegisterField(500, "raw status", "1", _raw_status, "status"),),
        )

    def status_view(self, status: int) -> StatusView:
        return StatusView(
            running=status != 0,
            tripped=False,
            state="running" if status else "stopped",
            fields={"raw": status},
        )

    def monitor_view(self, monitor: int) -> MonitorView:
        return MonitorView(output_frequency_hz=float(monitor))

    def trip(self, number: int) -> Trip:
        return Trip(f"T{number}", number, None, None)

    def trip_log(self, history: Any) -> TripLog:
        raise LocalProtocolError("toy units keep no trip history")

    def extras(self, status: int | None, monitor: Any, trips: Any) -> ToyExtras:
        return ToyExtras(status)

    async def read_set_frequency(self, drive: ToyDrive) -> float:
        return float(await drive.read("set"))

    async def read_trips(self, drive: ToyDrive) -> Any:
        raise LocalProtocolError("toy units keep no trip history")

    async def read_latest_trip(self, drive: ToyDrive) -> Trip | None:
        return None

    async def reset(self, drive: ToyDrive) -> None:
        await drive.write("status", 0)

    def status_rows(self, status: int, monitor: int) -> list[tuple[str, str]]:
        return [("state", self.status_view(status).state), ("speed", f"{monitor} Hz")]

    def trip_codes(self) -> Sequence[Trip]:
        return ()

    def nak_hint(self, code: int, command: str) -> str | None:
        return None

    def absent(self, code: int) -> bool:
        return code == 2  # "#NN 2": no such register

    def request_describer(self, dialect: Any) -> Callable[[bytes], str] | None:
        return None


TOY_PROFILE: Final = ToyProfile()
