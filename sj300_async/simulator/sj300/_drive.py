"""A simulated SJ300 drive: the sans-IO model behind one node address.

:meth:`SimulatedDrive.handle` takes a parsed :class:`~sj300_async.Request`
and the current time and returns the reply a real drive would give (or
None for a broadcast). Time is always passed in (``now``, seconds on any
monotonic scale); the drive integrates its ramps and hour counters over the
time between calls, so a test moves time explicitly and nothing sleeps.

This module holds what the drive does with each command, and its faces
for inspection and outside events. The model they work on (the drive's
inputs and output, and what they make of each other) is in
:mod:`._drive_model`; the run state machine is in :mod:`._motion`, the
status codes in :mod:`._status`, the parameter table and its limits in
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

import functools
import logging
from collections.abc import Callable, Mapping
from types import MappingProxyType
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
    InputTerminal,
    InverterStatus,
    MonitorData,
    NakCode,
    NakReply,
    Reply,
    Request,
    TripCode,
    TripHistory,
    encode_monitor,
    encode_status,
    encode_trip_history,
)
from ...wire import Direction, LocalProtocolError
from .._motion import Output, RunState
from ._drive_model import DriveModel
from ._memory import ParameterMemory
from ._parameters_table import (
    KEPT_BY_INITIALIZATION,
    SERIAL_CONTROL,
    SOURCE_SERIAL,
    Country,
    factory_table,
)
from ._trips import overcurrent_code

__all__ = ["DEFAULT_EEPROM_WRITE_S", "DEFAULT_PROCESSING_S", "SimulatedDrive"]

_log = logging.getLogger("sj300_async.simulator")

#: Time a drive needs after a request's CR before it can answer, on top of C078.
DEFAULT_PROCESSING_S: Final = 0.001
#: Time an EEPROM write (command 0A) takes; command 09 answers 00 meanwhile.
DEFAULT_EEPROM_WRITE_S: Final = 0.05

_RUN_MODES: Final = {b"0": Direction.STOP, b"1": Direction.FORWARD, b"2": Direction.REVERSE}

# Terminal bits as plain ints, as in the model: IntFlag arithmetic runs enum's Python code.
_RS: Final = InputTerminal.RS.value
_EXT: Final = InputTerminal.EXT.value

Result = Reply | NakCode
Handler = Callable[["SimulatedDrive", bytes, float], Result]


@functools.cache
def _shared_table(country: Country, *, factory_defaults: bool) -> Mapping[str, int]:
    """The parameter values every drive made alike starts with, shared (the node's own,
    C072, aside): see :class:`ParameterMemory`."""
    table = factory_table(country, 0)
    if not factory_defaults:
        table |= SERIAL_CONTROL
    return MappingProxyType(table)


class SimulatedDrive(DriveModel):
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
        base = _shared_table(Country(country), factory_defaults=factory_defaults)
        memory = ParameterMemory(base, {"C072": node}, write_s=eeprom_write_s)
        super().__init__(node, memory)
        self.processing_s = processing_s
        #: How many times command 0B asked to recalculate the motor constants.
        self.recalculations = 0
        #: Codes (upper case) this drive answers as it does a code it does not
        #: know (NAK 16 to reads and writes), as a firmware without them would;
        #: its model still uses their values. A test's hook: add to it at any time.
        self.withheld_parameters: set[str] = set()
        self._history_reply: tuple[TripHistory, DataReply] | None = None

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
    def run_command(self) -> Direction:
        """The run command given over the serial link (command 00) that it obeys now.

        What the drive was told, not what it does: a drive told to stop may
        still be ramping down (:meth:`state`).
        """
        return self._serial_run

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
        if code not in self._memory or code in self.withheld_parameters:
            return self._nak(NakCode.ABNORMAL_PARAMETER, data, "unknown parameter")
        return AckDataReply(self.node, b"%08d" % self._memory[code])

    def _cmd_write_parameter(self, data: bytes, now: float) -> Result:
        code = data[:4].decode("ascii").upper()
        raw = int(data[4:])
        reason = "unknown parameter" if code in self.withheld_parameters else None
        reason = reason or self._memory.refusal(code, raw)
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
