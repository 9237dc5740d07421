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

from ...sj300.codec import (
    ASSIGNED_INPUT_BITS,
    BROADCAST,
    MAX_NODE,
    MIN_NODE,
    AckDataReply,
    AckReply,
    Command,
    DataReply,
    InputMonitor,
    InputTerminal,
    InverterStatus,
    MonitorData,
    NakCode,
    NakReply,
    OutputTerminal,
    Reply,
    Request,
    TripCode,
    TripHistory,
    TripRecord,
    encode_monitor,
    encode_status,
    encode_trip_history,
    motor_capacity_kw,
)
from ...wire import Direction, LocalProtocolError
from .._electrical import MotorRating, electrical
from .._motion import Output, Ramp, RunState, advance, classify, settled
from ._memory import ParameterMemory
from ._parameters_table import (
    KEPT_BY_INITIALIZATION,
    SERIAL_CONTROL,
    SOURCE_SERIAL,
    SOURCE_TERMINAL,
    Country,
    factory_table,
)
from ._status import inverter_status, trip_status_a, trip_status_c
from ._trips import TripLog, overcurrent_code, trip_status_b

__all__ = ["DEFAULT_EEPROM_WRITE_S", "DEFAULT_PROCESSING_S", "SimulatedDrive"]

_log = logging.getLogger("sj300_async.simulator")

#: Time a drive needs after a request's CR before it can answer, on top of C078.
DEFAULT_PROCESSING_S: Final = 0.001
#: Time an EEPROM write (command 0A) takes; command 09 answers 00 meanwhile.
DEFAULT_EEPROM_WRITE_S: Final = 0.05

_HOUR_S: Final = 3600.0
_RUN_MODES: Final = {b"0": Direction.STOP, b"1": Direction.FORWARD, b"2": Direction.REVERSE}

# Terminal bits as plain ints: IntFlag arithmetic runs enum's Python code on every
# operation, and the run command is worked out several times per request.
_FW: Final = InputTerminal.FW.value
_RV: Final = InputTerminal.RV.value
_FRS: Final = InputTerminal.FRS.value
_RS: Final = InputTerminal.RS.value
_EXT: Final = InputTerminal.EXT.value

# Bits 1..8 of monitor item 5 are the intelligent input terminals 1..8.
_INPUT_TERMINAL_CODES: Final = tuple(f"C00{i}" for i in range(1, 9))

# Making an IntFlag from an int runs enum's Python code; the monitor makes two per
# request. Both flags have few values (9 and 3 bits), so each is made once.
_INPUT_MONITORS: Final[dict[int, InputMonitor]] = {}
_AL: Final = OutputTerminal.AL.value
_OUT11: Final = OutputTerminal.OUT11.value
_OUT12: Final = OutputTerminal.OUT12.value
_OUTPUT_TERMINALS: Final = tuple(
    OutputTerminal(bits) for bits in range((_AL | _OUT11 | _OUT12) + 1)
)

Result = Reply | NakCode
Handler = Callable[["SimulatedDrive", bytes, float], Result]


class _Settings:
    """What the model reads from the parameters, worked out once per change of RAM.

    Every request needs these several times, and they change only when a
    parameter is written: a drive keeps one, and reads it again when the
    memory's ``version`` has moved past the one it was read at.
    """

    __slots__ = ("input_functions", "ramp", "rating", "setpoint_hz", "source", "version", "wait_s")

    def __init__(self, memory: ParameterMemory) -> None:
        self.version = memory.version
        #: A002, the run command source.
        self.source = memory["A002"]
        self.setpoint_hz = memory["F001"] / 100
        self.ramp = Ramp.from_times(memory["A004"] / 10, memory["F002"] / 100, memory["F003"] / 100)
        kw = motor_capacity_kw(memory["H003"], memory["B085"])
        self.rating = MotorRating(
            voltage_v=float(memory["A082"]),
            current_a=memory["B012"] / 10,
            # B085 may change after H003 was set; a code without a capacity reads as 0 kW.
            power_kw=kw or 0.0,
            base_hz=memory["A003"] / 10,
        )
        #: C001..C008: the command 02 bit each intelligent input terminal 1..8 shows.
        self.input_functions = tuple(memory[code] for code in _INPUT_TERMINAL_CODES)
        #: C078 in seconds.
        self.wait_s = memory["C078"] / 1000


class _Snapshot:
    """The model between two changes: the run state and what the replies make of it.

    It describes the drive's present output under its present inputs (the
    latches and the parameters), so it stays true until one of them
    changes: the drive drops it when a latch changes or the output moves,
    and when the memory's version has moved past the one it was taken at.
    The replies built from it are kept in it, so a drive that keeps being
    asked while nothing changes answers from here.
    """

    __slots__ = (
        "command",
        "cut",
        "monitor",
        "monitor_reply",
        "outputting",
        "state",
        "status",
        "status_reply",
        "steady",
        "still",
        "version",
    )

    def __init__(
        self, version: int, command: Direction, state: RunState, *, cut: bool, steady: bool
    ) -> None:
        self.version = version
        #: The run command the drive obeys.
        self.command = command
        self.state = state
        self.outputting = state.outputting
        #: A trip or FRS holds the output at 0 Hz, whatever the run command.
        self.cut = cut
        #: The output stays as it is however much time passes (nothing to advance).
        self.steady = steady
        #: An advance by no time has left the output as it is (so would the next one).
        self.still = False
        self.status: InverterStatus | None = None
        self.status_reply: DataReply | None = None
        self.monitor: MonitorData | None = None
        self.monitor_reply: DataReply | None = None


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
        self._settings_cache = _Settings(self._memory)
        self._trips = TripLog()
        self._clock: float | None = None
        self._output = Output()
        # The latches: with the parameters, the model's inputs. Whatever changes one
        # (or the output, outside _advance) calls _changed().
        self._serial_run = Direction.STOP
        self._terminals = 0
        self._tripped = False
        self._snapshot_cache: _Snapshot | None = None
        self._history_reply: tuple[TripHistory, DataReply] | None = None
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
        return self._settings().wait_s + self.processing_s

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
        return self._status(self._snapshot())

    def monitor(self, now: float) -> MonitorData:
        """What command 03 reports at *now*."""
        self._advance(now)
        return self._monitor(self._snapshot())

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
        self._changed()
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
        self._changed()

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
            self._changed()
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
        self._changed()  # before _trip, which records the state the new terminals make
        if rising & _EXT:
            self._trip(TripCode.EXTERNAL)
        return AckReply(self.node)

    # The three reads answer the same reply object while nothing changes (kept in the
    # snapshot, or with the history it encodes): a reply is immutable, and the bus
    # reuses the frame it encoded for the previous one.

    def _cmd_read_monitor(self, data: bytes, now: float) -> Result:
        self._advance(now)
        snapshot = self._snapshot()
        monitor = self._monitor(snapshot)
        if snapshot.monitor_reply is None:
            snapshot.monitor_reply = DataReply(self.node, encode_monitor(monitor))
        return snapshot.monitor_reply

    def _cmd_read_status(self, data: bytes, now: float) -> Result:
        self._advance(now)
        snapshot = self._snapshot()
        if snapshot.status_reply is None:
            snapshot.status_reply = DataReply(self.node, encode_status(self._status(snapshot)))
        return snapshot.status_reply

    def _cmd_read_trip_history(self, data: bytes, now: float) -> Result:
        history = self._trips.history()
        cached = self._history_reply
        if cached is None or cached[0] is not history:
            cached = self._history_reply = (
                history,
                DataReply(self.node, encode_trip_history(history)),
            )
        return cached[1]

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
            self._changed()
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
    #
    # The inputs (latches and parameters) change only at requests and events, while
    # every request reads the run state several times: what the inputs make of the
    # output is kept in a _Snapshot until something changes (see _changed), and what
    # the parameters give in _Settings until RAM is written.

    def _changed(self) -> None:
        """Drop the snapshot: call after changing a latch, or the output outside _advance."""
        self._snapshot_cache = None

    def _settings(self) -> _Settings:
        settings = self._settings_cache
        if settings.version != self._memory.version:
            settings = self._settings_cache = _Settings(self._memory)
        return settings

    def _snapshot(self) -> _Snapshot:
        """The run state of the present output under the present inputs."""
        snapshot = self._snapshot_cache
        if snapshot is None or snapshot.version != self._memory.version:
            snapshot = self._snapshot_cache = self._take_snapshot()
        return snapshot

    def _take_snapshot(self) -> _Snapshot:
        settings = self._settings()
        command = self._run_command(settings.source)
        free_run = bool(self._terminals & _FRS)
        output = self._output
        state = classify(
            output, command, settings.setpoint_hz, tripped=self._tripped, free_run=free_run
        )
        cut = self._tripped or free_run
        if cut:  # _advance holds the output at Output()
            steady = output.hz == 0 and output.direction is Direction.STOP
        else:
            steady = settled(output, command, settings.setpoint_hz)
        return _Snapshot(settings.version, command, state, cut=cut, steady=steady)

    def _advance(self, now: float) -> None:
        """Bring the drive to *now*: counters, then the output along its ramps.

        Time never runs backwards: an earlier *now* (another server's clock)
        counts as no time at all.
        """
        clock = now if self._clock is None else self._clock
        dt = now - clock
        if not dt > 0:
            dt = 0.0
        self._clock = clock + dt
        self._power_on_s += dt
        snapshot = self._snapshot()
        # Hours only: the state at the start of the span is accurate enough.
        if snapshot.outputting:
            self._run_s += dt
        if snapshot.steady or (snapshot.still and not dt):
            # advance() would hand the output back as it is: at its goal whatever the
            # span (steady), or already advanced at this instant (still).
            return
        if snapshot.cut:
            output = Output()
        else:
            settings = self._settings()
            output = advance(
                self._output, snapshot.command, settings.setpoint_hz, settings.ramp, dt
            )
        if output is self._output:  # advance() returns an unchanged output as it is
            # advance() depends only on the output and the inputs: at this instant the
            # next one would leave it as it is again.
            if not dt:
                snapshot.still = True
        else:
            self._output = output
            self._changed()

    def _state(self) -> RunState:
        return self._snapshot().state

    def _run_command(self, source: int) -> Direction:
        """The run command the drive obeys, with A002 = *source* (see the module docstring)."""
        if self._tripped:
            return Direction.STOP
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

    def _status(self, snapshot: _Snapshot) -> InverterStatus:
        """Command 04's status, from *snapshot* (the present one)."""
        if snapshot.status is None:
            snapshot.status = inverter_status(snapshot.state, self._output, snapshot.command)
        return snapshot.status

    def _monitor(self, snapshot: _Snapshot) -> MonitorData:
        """Command 03's monitor block, from *snapshot* (the present one).

        Only the hour counters move while the snapshot holds: the block is
        kept in it and made again when one of them has ticked over.
        """
        run_time_h = int(self._run_s // _HOUR_S)
        power_on_time_h = int(self._power_on_s // _HOUR_S)
        monitor = snapshot.monitor
        if (
            monitor is not None
            and monitor.run_time_h == run_time_h
            and monitor.power_on_time_h == power_on_time_h
        ):
            return monitor
        state = snapshot.state
        output = self._output
        values = electrical(state, output.hz, self._settings().rating)
        snapshot.monitor_reply = None  # it encodes the block this one replaces
        monitor = snapshot.monitor = MonitorData(
            output_frequency_hz=output.hz,
            output_current_a=values.current_a,
            direction=output.direction,
            pid_feedback_percent=0.0,
            input_terminals=self._input_monitor(),
            output_terminals=self._output_terminals(state),
            frequency_conversion=output.hz,
            output_torque_percent=values.torque_percent,
            output_voltage_v=values.voltage_v,
            power_kw=values.power_kw,
            run_time_h=run_time_h,
            power_on_time_h=power_on_time_h,
        )
        return monitor

    def _trip(self, code: int) -> bool:
        if self._tripped:
            return False
        state = self._state()
        values = electrical(state, self._output.hz, self._settings().rating)
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
        self._changed()
        return True

    def _input_monitor(self) -> InputMonitor:
        terminals = self._terminals
        bits = terminals & _FW
        for terminal, function in enumerate(self._settings().input_functions, start=1):
            if terminals >> function & 1:
                bits |= 1 << terminal
        monitor = _INPUT_MONITORS.get(bits)
        if monitor is None:
            monitor = _INPUT_MONITORS[bits] = InputMonitor(bits)
        return monitor

    def _output_terminals(self, state: RunState) -> OutputTerminal:
        bits = 0
        if state is RunState.TRIPPED:
            bits |= _AL
        if state.outputting:
            bits |= _OUT11
        if state is RunState.CONSTANT_SPEED and self._output.hz > 0:
            bits |= _OUT12
        return _OUTPUT_TERMINALS[bits]


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
