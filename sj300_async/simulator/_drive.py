"""A simulated SJ300 drive: the sans-IO model behind one node address.

:meth:`SimulatedDrive.handle` takes a parsed :class:`~sj300_async.Request`
and the current time and returns the reply a real drive would give (or
None for a broadcast). Time is always passed in (``now``, seconds on any
monotonic scale); the drive integrates its ramps and hour counters over the
time between calls, so a test moves time explicitly and nothing sleeps.

The run state machine is in :mod:`._motion`, the status codes in
:mod:`._status`, the parameter table and its limits in
:mod:`._parameters_table`, RAM and EEPROM in :mod:`._memory`.

Decisions a real drive leaves open (the seeds do not say):

- Memory (RAM, EEPROM, what 09 answers): see :mod:`._memory`.
- Run command source: command 00 needs A002 = 03, command 01 needs A001 =
  03 (else NAK 13; A003 is the base frequency, see ``_parameters.py``). The
  FW / RV bits of command 02 are terminals: they run the drive when A002
  selects the terminals (01), and also when it selects serial (03), since
  command 02 is itself serial. A held terminal overrides the command 00
  state; FW and RV together mean stop, as on the terminal strip.
- Every frequency source reads F001; analog inputs are not modelled. 07 may
  write F001 whatever A001 says (the manual offers it as the indirect way).
- A trip cuts the output, latches until the RS terminal rises (or a power
  cycle) and clears the command 00 run state; a terminal run command still
  held restarts the drive after the reset. While tripped, command 00 is
  acknowledged and ignored. EXT rising trips with E12. A trip while tripped
  is not recorded (the drive is already stopped).
- Command 00 data other than 0/1/2, command 01 above A004, a command 02
  with unassigned bits, unknown parameter codes and values out of range
  get NAK 16. Command 08 while the output runs gets NAK 13.
- B084 = 00 makes 08 clear the trip history only (the SJ300 manual's
  meaning of 00; the seed describes only 01 and 02).
- Monitor item 5 shows the terminals set by command 02 on the inputs that
  C001..C008 assign their functions to; item 6 shows AL on a trip, 11 as
  the RUN signal and 12 as frequency arrival (FA1).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import Final

from .._codes import Direction, NakCode
from .._commands import Command
from .._constants import BROADCAST, MAX_NODE, MIN_NODE
from .._errors import LocalProtocolError
from .._events import AckDataReply, AckReply, DataReply, NakReply, Reply
from .._parameters import motor_capacity_kw
from .._payloads import InverterStatus, MonitorData, TripHistory, TripRecord
from .._reply_encoding import encode_monitor, encode_status, encode_trip_history
from .._requests import Request
from .._terminals import ASSIGNED_INPUT_BITS, InputMonitor, InputTerminal, OutputTerminal
from ._electrical import MotorRating, electrical
from ._memory import ParameterMemory
from ._motion import Output, Ramp, RunState, advance, classify
from ._parameters_table import (
    KEPT_BY_INITIALIZATION,
    SERIAL_CONTROL,
    SOURCE_SERIAL,
    SOURCE_TERMINAL,
    Country,
    factory_table,
)
from ._status import inverter_status, trip_status_a, trip_status_c
from ._trips import TripCode, TripLog, overcurrent_code, trip_status_b

__all__ = ["DEFAULT_EEPROM_WRITE_S", "DEFAULT_PROCESSING_S", "SimulatedDrive"]

_log = logging.getLogger("sj300_async.simulator")

#: Time a drive needs after a request's CR before it can answer, on top of C078.
DEFAULT_PROCESSING_S: Final = 0.001
#: Time an EEPROM write (command 0A) takes; command 09 answers 00 meanwhile.
DEFAULT_EEPROM_WRITE_S: Final = 0.05

_HOUR_S: Final = 3600.0
_RUN_MODES: Final = {b"0": Direction.STOP, b"1": Direction.FORWARD, b"2": Direction.REVERSE}

# Terminal bits as plain ints: IntFlag arithmetic costs microseconds per operation,
# and the run command is worked out several times per request.
_FW: Final = InputTerminal.FW.value
_RV: Final = InputTerminal.RV.value
_FRS: Final = InputTerminal.FRS.value
_RS: Final = InputTerminal.RS.value
_EXT: Final = InputTerminal.EXT.value

# Bits 1..8 of monitor item 5 are the intelligent input terminals 1..8.
_INPUT_TERMINAL_CODES: Final = tuple(f"C00{i}" for i in range(1, 9))

Result = Reply | NakCode
Handler = Callable[["SimulatedDrive", bytes, float], Result]


class SimulatedDrive:
    """One virtual SJ300 at one node address (see the module docstring for its behaviour).

    Args:
        node: the address, 1..32 (also its C072).
        country: B085, whose factory values the drive starts with.
        factory_defaults: start with the true factory values; by default the
            drive starts configured for serial control (A001 = A002 = 03),
            as if the integrator had stored that.
        processing_s: time the drive needs before answering, on top of C078.
        eeprom_write_s: duration of an EEPROM write (command 0A).

    Raises:
        LocalProtocolError: *node* is not 1..32.
    """

    def __init__(
        self,
        node: int,
        *,
        country: Country = Country.EUROPE,
        factory_defaults: bool = False,
        processing_s: float = DEFAULT_PROCESSING_S,
        eeprom_write_s: float = DEFAULT_EEPROM_WRITE_S,
    ) -> None:
        if isinstance(node, bool) or not isinstance(node, int) or not MIN_NODE <= node <= MAX_NODE:
            raise LocalProtocolError(f"a drive's node is 1..32, got {node!r}")
        self.node = node
        self.processing_s = processing_s
        #: How many times command 0B asked to recalculate the motor constants.
        self.recalculations = 0
        table = factory_table(Country(country), node)
        if not factory_defaults:
            table |= SERIAL_CONTROL
        self._memory = ParameterMemory(table, write_s=eeprom_write_s)
        self._trips = TripLog()
        self._clock: float | None = None
        self._output = Output()
        self._serial_run = Direction.STOP
        self._terminals = 0
        self._tripped = False
        self._run_s = 0.0
        self._power_on_s = 0.0

    def __repr__(self) -> str:
        return f"SimulatedDrive(node={self.node}, state={self._state().value})"

    # -- inspection ---------------------------------------------------------

    @property
    def parameters(self) -> Mapping[str, int]:
        """The raw parameter values in RAM (what 06 reads), read-only."""
        return self._memory.ram

    @property
    def stored_parameters(self) -> Mapping[str, int]:
        """The raw parameter values in EEPROM (what a power cycle restores), read-only."""
        return self._memory.eeprom

    @property
    def terminals(self) -> InputTerminal:
        """The intelligent input terminals as command 02 last set them."""
        return InputTerminal(self._terminals)

    @property
    def tripped(self) -> bool:
        """True while a trip is latched."""
        return self._tripped

    @property
    def reply_delay_s(self) -> float:
        """Time from a request's CR to the reply's first byte: C078 plus processing."""
        return self._memory["C078"] / 1000 + self.processing_s

    def state(self, now: float) -> RunState:
        """The run state at *now*."""
        self._advance(now)
        return self._state()

    def output_hz(self, now: float) -> float:
        """The output frequency at *now*, unrounded."""
        self._advance(now)
        return self._output.hz

    def status(self, now: float) -> InverterStatus:
        """What command 04 reports at *now*."""
        self._advance(now)
        return inverter_status(self._state(), self._output, self._run_command())

    def monitor(self, now: float) -> MonitorData:
        """What command 03 reports at *now*."""
        self._advance(now)
        state = self._state()
        values = electrical(state, self._output.hz, self._rating())
        return MonitorData(
            output_frequency_hz=self._output.hz,
            output_current_a=values.current_a,
            direction=self._output.direction,
            pid_feedback_percent=0.0,
            input_terminals=self._input_monitor(),
            output_terminals=self._output_terminals(state),
            frequency_conversion=self._output.hz,
            output_torque_percent=values.torque_percent,
            output_voltage_v=values.voltage_v,
            power_kw=values.power_kw,
            run_time_h=int(self._run_s // _HOUR_S),
            power_on_time_h=int(self._power_on_s // _HOUR_S),
        )

    def trip_history(self) -> TripHistory:
        """What command 05 reports."""
        return self._trips.history()

    # -- events that do not come over the line -------------------------------

    def trip(self, code: int | None = None, *, now: float) -> bool:
        """Trip the drive at *now*, as a fault inside it would.

        Args:
            code: the trip factor (7 for E07); by default the over-current
                code E01..E04 that fits what the drive is doing.

        Returns:
            False when the drive was already tripped (nothing is recorded).

        Raises:
            LocalProtocolError: *code* is not 1..99.
        """
        self._advance(now)
        if code is None:
            code = overcurrent_code(self._state())
        if isinstance(code, bool) or not isinstance(code, int) or not 1 <= code <= 99:
            raise LocalProtocolError(f"a trip factor is 1..99, got {code!r}")
        return self._trip(code)

    def reset(self, now: float) -> bool:
        """Clear a latched trip, as the RS terminal does. Returns False if there was none."""
        self._advance(now)
        was_tripped = self._tripped
        self._tripped = False
        self._advance(now)
        return was_tripped

    def power_cycle(self, now: float) -> None:
        """Switch the drive off and on at *now*: RAM reloads from EEPROM, trips and inputs clear."""
        self._advance(now)
        self._memory.power_cycle()
        self._output = Output()
        self._serial_run = Direction.STOP
        self._terminals = 0
        self._tripped = False

    def set_parameter(self, code: str, raw: int, *, store: bool = True) -> None:
        """Set a parameter from outside the line (e.g. a server's --wait-ms option).

        Args:
            store: also write EEPROM, so the value survives a power cycle.

        Raises:
            LocalProtocolError: the drive does not know *code* or refuses *raw*.
        """
        code = code.upper()
        reason = self._memory.refusal(code, raw)
        if reason is not None:
            raise LocalProtocolError(f"{code} = {raw} refused: {reason}")
        self._memory.write(code, raw, store=store)

    def set_wait_ms(self, wait_ms: int) -> None:
        """Set (and store) C078, the wait before every reply, in ms.

        Raises:
            LocalProtocolError: *wait_ms* is not 0..1000.
        """
        self.set_parameter("C078", wait_ms)

    # -- the line -------------------------------------------------------------

    def handle(self, request: Request, now: float) -> Reply | None:
        """Execute *request* at *now*; return the reply, or None for a broadcast.

        The caller (the bus) routes: *request* is for this node or for all.
        """
        self._advance(now)
        result = _HANDLERS[request.command](self, request.data, now)
        self._advance(now)  # apply what is instantaneous (a free-run cut, a start)
        if request.node == BROADCAST:
            return None
        if isinstance(result, NakCode):
            return NakReply(self.node, result)
        return result

    def _nak(self, code: NakCode, request_data: bytes, why: str) -> NakCode:
        _log.debug("node %02d: NAK %02d (%s) for data %r", self.node, code, why, request_data)
        return code

    def _cmd_run(self, data: bytes, now: float) -> Result:
        direction = _RUN_MODES.get(data)
        if direction is None:
            return self._nak(NakCode.ABNORMAL_PARAMETER, data, "run mode is 0, 1 or 2")
        if self._memory["A002"] != SOURCE_SERIAL:
            return self._nak(NakCode.EXECUTION_DISABLED, data, "A002 is not 03")
        if not self._tripped:
            self._serial_run = direction
        return AckReply(self.node)

    def _cmd_set_frequency(self, data: bytes, now: float) -> Result:
        if self._memory["A001"] != SOURCE_SERIAL:
            return self._nak(NakCode.EXECUTION_DISABLED, data, "A001 is not 03")
        centi_hz = int(data)
        reason = self._memory.refusal("F001", centi_hz)
        if reason is not None:
            return self._nak(NakCode.ABNORMAL_PARAMETER, data, reason)
        self._memory.write("F001", centi_hz)
        return AckReply(self.node)

    def _cmd_set_terminals(self, data: bytes, now: float) -> Result:
        mask = int(data, 16)
        if mask & ~ASSIGNED_INPUT_BITS:
            return self._nak(NakCode.ABNORMAL_PARAMETER, data, "unassigned terminal bits")
        rising = mask & ~self._terminals
        self._terminals = mask
        if rising & _RS:
            self._tripped = False
        if rising & _EXT:
            self._trip(TripCode.EXTERNAL)
        return AckReply(self.node)

    def _cmd_read_monitor(self, data: bytes, now: float) -> Result:
        return DataReply(self.node, encode_monitor(self.monitor(now)))

    def _cmd_read_status(self, data: bytes, now: float) -> Result:
        return DataReply(self.node, encode_status(self.status(now)))

    def _cmd_read_trip_history(self, data: bytes, now: float) -> Result:
        return DataReply(self.node, encode_trip_history(self._trips.history()))

    def _cmd_read_parameter(self, data: bytes, now: float) -> Result:
        code = data.decode("ascii").upper()
        if code not in self._memory:
            return self._nak(NakCode.ABNORMAL_PARAMETER, data, "unknown parameter")
        return AckDataReply(self.node, b"%08d" % self._memory[code])

    def _cmd_write_parameter(self, data: bytes, now: float) -> Result:
        code = data[:4].decode("ascii").upper()
        raw = int(data[4:])
        reason = self._memory.refusal(code, raw)
        if reason is not None:
            return self._nak(NakCode.ABNORMAL_PARAMETER, data, reason)
        self._memory.write(code, raw)
        return AckReply(self.node)

    def _cmd_initialize(self, data: bytes, now: float) -> Result:
        if self._state().outputting:
            return self._nak(NakCode.EXECUTION_DISABLED, data, "initialize while running")
        mode = self._memory["B084"]
        if mode in (0, 2):
            self._trips.clear()
        if mode in (1, 2):
            kept = {code: self._memory[code] for code in KEPT_BY_INITIALIZATION}
            self._memory.initialize(factory_table(Country(kept["B085"]), self.node) | kept)
            self._serial_run = Direction.STOP
        return AckReply(self.node)

    def _cmd_can_store(self, data: bytes, now: float) -> Result:
        return AckDataReply(self.node, b"01" if self._memory.can_store(now) else b"00")

    def _cmd_store(self, data: bytes, now: float) -> Result:
        self._memory.store(now)
        return AckReply(self.node)

    def _cmd_recalculate(self, data: bytes, now: float) -> Result:
        self.recalculations += 1
        return AckReply(self.node)

    # -- the model -------------------------------------------------------------

    def _advance(self, now: float) -> None:
        """Bring the drive to *now*: counters, then the output along its ramps.

        Time never runs backwards: an earlier *now* (another server's clock)
        counts as no time at all.
        """
        if self._clock is None:
            self._clock = now
        dt = max(0.0, now - self._clock)
        self._clock += dt
        self._power_on_s += dt
        # Hours only: the state at the start of the span is accurate enough.
        if self._state().outputting:
            self._run_s += dt
        if self._tripped or self._terminals & _FRS:
            self._output = Output()
        else:
            self._output = advance(
                self._output, self._run_command(), self._setpoint_hz(), self._ramp(), dt
            )

    def _state(self) -> RunState:
        return classify(
            self._output,
            self._run_command(),
            self._setpoint_hz(),
            tripped=self._tripped,
            free_run=bool(self._terminals & _FRS),
        )

    def _run_command(self) -> Direction:
        """The run command the drive obeys (see the module docstring)."""
        if self._tripped:
            return Direction.STOP
        source = self._memory["A002"]
        if source in (SOURCE_TERMINAL, SOURCE_SERIAL):
            forward = bool(self._terminals & _FW)
            reverse = bool(self._terminals & _RV)
            if forward and reverse:
                return Direction.STOP
            if forward:
                return Direction.FORWARD
            if reverse:
                return Direction.REVERSE
        return self._serial_run if source == SOURCE_SERIAL else Direction.STOP

    def _setpoint_hz(self) -> float:
        return self._memory["F001"] / 100

    def _ramp(self) -> Ramp:
        return Ramp.from_times(
            self._memory["A004"] / 10, self._memory["F002"] / 100, self._memory["F003"] / 100
        )

    def _rating(self) -> MotorRating:
        kw = motor_capacity_kw(self._memory["H003"], self._memory["B085"])
        return MotorRating(
            voltage_v=float(self._memory["A082"]),
            current_a=self._memory["B012"] / 10,
            # B085 may change after H003 was set; a code without a capacity reads as 0 kW.
            power_kw=kw or 0.0,
            base_hz=self._memory["A003"] / 10,
        )

    def _trip(self, code: int) -> bool:
        if self._tripped:
            return False
        state = self._state()
        values = electrical(state, self._output.hz, self._rating())
        self._trips.record(
            TripRecord(
                trip_factor=code,
                status_a=trip_status_a(state),
                status_b=trip_status_b(code),
                status_c=trip_status_c(state, self._output),
                output_frequency_hz=self._output.hz,
                run_time_h=int(self._run_s // _HOUR_S),
                output_current_a=values.current_a,
                output_voltage_v=values.voltage_v,
                power_on_time_h=int(self._power_on_s // _HOUR_S),
            )
        )
        _log.debug("node %02d: trip E%02d while %s", self.node, code, state.value)
        self._tripped = True
        self._serial_run = Direction.STOP
        self._output = Output()
        return True

    def _input_monitor(self) -> InputMonitor:
        bits = self._terminals & _FW
        for terminal, code in enumerate(_INPUT_TERMINAL_CODES, start=1):
            if self._terminals >> self._memory[code] & 1:
                bits |= 1 << terminal
        return InputMonitor(bits)

    def _output_terminals(self, state: RunState) -> OutputTerminal:
        bits = OutputTerminal(0)
        if state is RunState.TRIPPED:
            bits |= OutputTerminal.AL
        if state.outputting:
            bits |= OutputTerminal.OUT11
        if state is RunState.CONSTANT_SPEED and self._output.hz > 0:
            bits |= OutputTerminal.OUT12
        return bits


_HANDLERS: Final[dict[Command, Handler]] = {
    Command.RUN: SimulatedDrive._cmd_run,
    Command.SET_FREQUENCY: SimulatedDrive._cmd_set_frequency,
    Command.SET_TERMINALS: SimulatedDrive._cmd_set_terminals,
    Command.READ_MONITOR: SimulatedDrive._cmd_read_monitor,
    Command.READ_STATUS: SimulatedDrive._cmd_read_status,
    Command.READ_TRIP_HISTORY: SimulatedDrive._cmd_read_trip_history,
    Command.READ_PARAMETER: SimulatedDrive._cmd_read_parameter,
    Command.WRITE_PARAMETER: SimulatedDrive._cmd_write_parameter,
    Command.INITIALIZE: SimulatedDrive._cmd_initialize,
    Command.CAN_STORE: SimulatedDrive._cmd_can_store,
    Command.STORE: SimulatedDrive._cmd_store,
    Command.RECALCULATE: SimulatedDrive._cmd_recalculate,
}
