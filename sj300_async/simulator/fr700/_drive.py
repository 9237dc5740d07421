"""A simulated FR-700 drive: the sans-IO model behind one station number.

:meth:`Fr700SimulatedDrive.handle` takes a parsed request and the current
time and returns the reply a real drive would give (None for the inverter
reset, which is never answered). Time is passed in; the output follows its
ramps between calls (the run state machine of :mod:`.._motion`, shared with
the SJ300 simulator).

What it models, from the FR-700 reference:

- Set frequency in RAM (HED, read H6D) and EEPROM (HEE writes both, H6E
  reads EEPROM); a reset or power cycle reloads RAM from EEPROM.
- Run command HFA (and the extended HF9): H02 forward, H04 reverse, both or
  neither stop; other bits are accepted and kept.
- Ramps from Pr.7 / Pr.8 (x 0.1 s between 0 Hz and Pr.20); 0 s is a step.
- Status H7A / H79: RUN, forward, reverse, SU (at the set frequency), FU
  (output at or above Pr.42), ABC1 and the fault bit while tripped; OL and
  IPF never.
- Monitors H6F / H70 / H71 (:mod:`._readings`).
- Operation mode H7B / HFB; parameters through the link-parameter
  extension H7F / HFF (bank 0..9: Pr.0..Pr.999); the second-parameter
  switch H6C / HEC, which selects the frequency (H00) or the analog value
  (H01) of the bias/gain parameters Pr.902..Pr.905; multi-command HF0;
  fault history H74..H77 and its clear HF4; parameter clear HFC; inverter
  reset HFD H9696.
- NAK codes as a drive gives them: 2 (sum), 3 (protocol), 7 (character)
  come from the request parser; A, B and C from here.

Decisions where the reference is silent:

- Writes that command the drive (run command, set frequency, parameters,
  multi-command, clears) need network operation mode (H0000), else NAK A.
  The drive starts in network mode, as one set up for the computer link
  (Pr.340 = 1); ``factory_defaults=True`` starts it in external mode.
  Changing the operation mode, or writing Pr.79, while the output runs is
  NAK A; an unknown mode is NAK C.
- A parameter or instruction the drive does not have is NAK B (the code
  addresses nothing), a value out of range NAK C, a bank above 9 NAK C.
  With Pr.77 (parameter write selection) = 1 every parameter write but
  Pr.77's is NAK A (see :mod:`._parameters`).
- HFD with data other than H9696 is NAK C (it is answered); HFD H9696 is
  not answered and the drive hears nothing for ``reset_s`` afterwards. The
  reset clears a trip, stops the output, returns the bank to 0 and the
  operation mode to the start mode, and reloads the RAM set frequency.
- A multi-command whose send or receive type is not 0/1 or 0..3 is NAK 3
  (a grammar error); a mode or range error of one half goes into the C1
  reply's error field for that half, the other half is still carried out.
- Special monitor selections (HF3) 1 (output frequency), 2 (current),
  3 (voltage) and 5 (set frequency) exist; others are NAK C.
- Fault codes: E.OC1 / E.OC2 / E.OC3 (H10 / H11 / H12) by what the output
  did, unless the caller names one; H74 holds the latest (low byte) and the
  second latest (high byte) fault, H75..H77 the older ones.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Final

from ...fr700.codec import (
    RESET_DATA,
    Fr700Ack,
    Fr700Data,
    Fr700Instruction,
    Fr700Nak,
    Fr700NakCode,
    Fr700OperationMode,
    Fr700Reply,
    Fr700StatusBits,
    HostRequest,
)
from ...wire import Direction, LocalProtocolError
from .._motion import Output, Ramp, RunState, advance, classify
from ._parameters import (
    BIAS_GAIN_ANALOG,
    BIAS_GAIN_ANALOG_MAX,
    COMMUNICATION,
    NOT_USED,
    PARAMETERS,
    WRITE_SELECTION,
    factory_values,
)
from ._readings import FaultCode, monitor, status_bits

__all__ = ["DEFAULT_PROCESSING_S", "Fr700SimulatedDrive"]

_log = logging.getLogger("sj300_async.simulator.fr700")

#: The simulated drive's own time to answer, on top of the waiting time. A real
#: drive takes about 12 ms (monitors) to 30 ms (parameters, EEPROM); the host's
#: time-outs allow for that, and tests need not wait for it.
DEFAULT_PROCESSING_S: Final = 0.001

I = Fr700Instruction  # noqa: E741
_NETWORK: Final = Fr700OperationMode.NETWORK
_CLEAR_CODES: Final = frozenset({0x9696, 0x9966, 0x5A5A, 0x55AA})
_SPECIAL_MONITORS: Final = frozenset({1, 2, 3, 5})
_FORWARD_BIT: Final = 0x02
_REVERSE_BIT: Final = 0x04


Result = Fr700Reply | Fr700NakCode | None
Handler = Callable[["Fr700SimulatedDrive", HostRequest, float], Result]


class Fr700SimulatedDrive:
    """One virtual FR-700 at one station (see the module docstring for its behaviour).

    Args:
        station: 0..31 (also its Pr.117).
        wait_field: the line's requests carry the waiting-time character
            (Pr.123 = 9999); else the drive waits its own Pr.123.
        factory_defaults: start in external operation mode, as from the factory.
        processing_s: the drive's time to answer on top of the waiting time.
        reset_s: how long the drive hears nothing after an inverter reset.

    Raises:
        LocalProtocolError: *station* is not 0..31.
    """

    def __init__(
        self,
        station: int,
        *,
        wait_field: bool = True,
        factory_defaults: bool = False,
        processing_s: float = DEFAULT_PROCESSING_S,
        reset_s: float = 0.0,
    ) -> None:
        if isinstance(station, bool) or not isinstance(station, int) or not 0 <= station <= 31:
            raise LocalProtocolError(f"an FR-700 station is 0..31, got {station!r}")
        self.station = station
        self.wait_field = wait_field
        self.processing_s = processing_s
        self.reset_s = reset_s
        self._parameters = factory_values()
        self._parameters[117] = station
        self._parameters[123] = NOT_USED if wait_field else 0
        self._parameters[340] = 0 if factory_defaults else 1
        self._analog = dict(BIAS_GAIN_ANALOG)  # the bias/gain parameters' other half
        self._freq_ram = 0  # x 0.01 Hz
        self._freq_eeprom = 0
        self._run_bits = 0
        self._mode = self._start_mode()
        self._bank = 0
        self._second_parameter = 0
        self._special_monitor = 1
        self._faults: list[int] = []  # latest first
        self._tripped = False
        self._output = Output()
        self._clock: float | None = None
        self._deaf_until = -math.inf
        #: The last data reply (E / C1), which a host's NAK (format F) asks for again.
        self.last_data_reply: Fr700Data | None = None

    def __repr__(self) -> str:
        return f"Fr700SimulatedDrive(station={self.station}, state={self._state().value})"

    # -- inspection -------------------------------------------------------------------

    @property
    def node(self) -> int:
        """The station (the name the fault hooks use)."""
        return self.station

    @property
    def parameters(self) -> Mapping[int, int]:
        """The raw parameter values, read-only."""
        return MappingProxyType(self._parameters)

    @property
    def bias_gain_analog(self) -> Mapping[int, int]:
        """The analog values (x 0.1 %) of the bias/gain parameters, read-only."""
        return MappingProxyType(self._analog)

    @property
    def operation_mode(self) -> Fr700OperationMode:
        """The operation mode now."""
        return self._mode

    @property
    def set_frequency_hz(self) -> float:
        """The set frequency in RAM, in Hz."""
        return self._freq_ram / 100

    @property
    def stored_frequency_hz(self) -> float:
        """The set frequency in EEPROM, in Hz."""
        return self._freq_eeprom / 100

    @property
    def parameter_bank(self) -> int:
        """The link-parameter extension (H7F) now."""
        return self._bank

    @property
    def tripped(self) -> bool:
        """True while a fault is latched."""
        return self._tripped

    @property
    def fault_history(self) -> tuple[int, ...]:
        """Fault codes, latest first (at most eight)."""
        return tuple(self._faults)

    def state(self, now: float) -> RunState:
        """The run state at *now*."""
        self._advance(now)
        return self._state()

    def output_hz(self, now: float) -> float:
        """The output frequency at *now*."""
        self._advance(now)
        return self._output.hz

    def status_bits(self, now: float) -> Fr700StatusBits:
        """The extended status (H79) at *now*; H7A is its low byte."""
        self._advance(now)
        return self._status_bits()

    def reply_delay_s(self, request: HostRequest) -> float:
        """Time from the request's end to the reply: the waiting time plus processing."""
        if request.wait_digit is not None:
            wait_ms = request.wait_digit * 10
        else:
            fixed = self._parameters[123]
            wait_ms = 0 if fixed == NOT_USED else fixed
        return wait_ms / 1000 + self.processing_s

    def hears(self, now: float) -> bool:
        """False while the drive restarts after an inverter reset."""
        return now >= self._deaf_until

    # -- events that do not come over the line ----------------------------------------------

    def trip(self, code: int | None = None, *, now: float) -> bool:
        """Trip the drive at *now*, as a fault inside it would.

        Args:
            code: the fault code (:class:`FaultCode`); by default the
                over-current code of what the output is doing.

        Returns:
            False when the drive was already tripped (nothing is recorded).

        Raises:
            LocalProtocolError: *code* is not 1..255.
        """
        self._advance(now)
        if self._tripped:
            return False
        if code is None:
            state = self._state()
            code = {
                RunState.ACCELERATING: FaultCode.OC1,
                RunState.CONSTANT_SPEED: FaultCode.OC2,
            }.get(state, FaultCode.OC3)
        if isinstance(code, bool) or not isinstance(code, int) or not 1 <= code <= 0xFF:
            raise LocalProtocolError(f"a fault code is 1..255, got {code!r}")
        self._faults = [code, *self._faults][:8]
        self._tripped = True
        self._run_bits = 0
        self._output = Output()
        _log.debug("station %02d: fault H%02X", self.station, code)
        return True

    def power_cycle(self, now: float) -> None:
        """Switch the drive off and on: RAM reloads from EEPROM, faults and run command clear."""
        self._advance(now)
        self._restart()

    def set_parameter(self, number: int, raw: int) -> None:
        """Set parameter *number* from outside the line, as at the operation panel.

        It takes what a write over the line would (whatever the operation
        mode, Pr.77 or the output); a bias/gain parameter's half is the one
        the second-parameter switch selects.

        Raises:
            LocalProtocolError: the drive has no such parameter, or refuses *raw*.
        """
        spec = PARAMETERS.get(number)
        if spec is None:
            raise LocalProtocolError(f"the drive has no Pr.{number}")
        if number in self._analog and self._second_parameter:
            if not 0 <= raw <= BIAS_GAIN_ANALOG_MAX:
                raise LocalProtocolError(f"Pr.{number} analog value {raw} is out of range")
            self._analog[number] = raw
            return
        if not spec.accepts(raw):
            raise LocalProtocolError(f"Pr.{number} = {raw} is out of range")
        self._parameters[number] = raw

    def set_wait_ms(self, wait_ms: int) -> None:
        """Set Pr.123, the drive's own waiting time in ms (used when requests carry none).

        Raises:
            LocalProtocolError: *wait_ms* is not 0..150, or the line uses the
                waiting-time field (the drive's Pr.123 is then 9999).
        """
        if self.wait_field:
            raise LocalProtocolError("the requests carry the waiting time: Pr.123 is 9999")
        if isinstance(wait_ms, bool) or not isinstance(wait_ms, int) or not 0 <= wait_ms <= 150:
            raise LocalProtocolError(f"Pr.123 waiting time is 0..150 ms, got {wait_ms!r}")
        self._parameters[123] = wait_ms

    # -- the line ------------------------------------------------------------------------------

    def handle(self, request: HostRequest, now: float) -> Fr700Reply | None:
        """Execute *request* at *now*; return the reply, or None (inverter reset)."""
        self._advance(now)
        code = request.instruction
        if code < 0x64:
            handler: Handler | None = Fr700SimulatedDrive._read_parameter
        elif 0x80 <= code < 0xE4:
            handler = Fr700SimulatedDrive._write_parameter
        else:
            handler = _HANDLERS.get(code)
        if handler is None:
            result: Result = Fr700NakCode.INSTRUCTION_CODE
        else:
            result = handler(self, request, now)
        self._advance(now)  # apply what is instantaneous (a start from 0 Hz)
        if isinstance(result, Fr700NakCode):
            _log.debug("station %02d: NAK %X to H%02X", self.station, result, code)
            result = Fr700Nak(self.station, result)
        self.last_data_reply = result if isinstance(result, Fr700Data) else None
        return result

    def _data(self, value: int, digits: int = 4) -> Fr700Data:
        return Fr700Data(self.station, b"%0*X" % (digits, value))

    def _ack(self) -> Fr700Ack:
        return Fr700Ack(self.station)

    # reads

    def _read_parameter(self, request: HostRequest, now: float) -> Result:
        number = self._bank * 100 + request.instruction
        if number not in self._parameters:
            return Fr700NakCode.INSTRUCTION_CODE
        if number in self._analog and self._second_parameter:
            return self._data(self._analog[number])
        return self._data(self._parameters[number])

    def _read_second_parameter(self, request: HostRequest, now: float) -> Result:
        return self._data(self._second_parameter, 2)

    def _read_frequency_ram(self, request: HostRequest, now: float) -> Result:
        return self._data(self._freq_ram)

    def _read_frequency_eeprom(self, request: HostRequest, now: float) -> Result:
        return self._data(self._freq_eeprom)

    def _read_output_frequency(self, request: HostRequest, now: float) -> Result:
        return self._data(self._monitor(1))

    def _read_output_current(self, request: HostRequest, now: float) -> Result:
        return self._data(self._monitor(2))

    def _read_output_voltage(self, request: HostRequest, now: float) -> Result:
        return self._data(self._monitor(3))

    def _read_special_monitor_selection(self, request: HostRequest, now: float) -> Result:
        return self._data(self._special_monitor, 2)

    def _read_fault_history(self, request: HostRequest, now: float) -> Result:
        pair = 2 * (request.instruction - I.FAULT_HISTORY)
        faults = [*self._faults, *[0] * 8][pair : pair + 2]  # empty slots read 00
        return self._data(faults[1] << 8 | faults[0])

    def _read_extended_status(self, request: HostRequest, now: float) -> Result:
        return self._data(self._status_bits())

    def _read_status(self, request: HostRequest, now: float) -> Result:
        return self._data(self._status_bits() & 0xFF, 2)

    def _read_operation_mode(self, request: HostRequest, now: float) -> Result:
        return self._data(self._mode)

    def _read_link_extension(self, request: HostRequest, now: float) -> Result:
        return self._data(self._bank, 2)

    # writes

    def _write_parameter(self, request: HostRequest, now: float) -> Result:
        number = self._bank * 100 + request.instruction - 0x80
        spec = PARAMETERS.get(number)
        if spec is None:
            return Fr700NakCode.INSTRUCTION_CODE
        if self._mode is not _NETWORK:
            return Fr700NakCode.MODE
        if self._parameters[WRITE_SELECTION] == 1 and number != WRITE_SELECTION:
            return Fr700NakCode.MODE  # write disabled
        if not spec.while_running and self._state().outputting:
            return Fr700NakCode.MODE
        raw = int(request.data, 16)
        if number in self._analog and self._second_parameter:
            if raw > BIAS_GAIN_ANALOG_MAX:
                return Fr700NakCode.DATA_RANGE
            self._analog[number] = raw
            return self._ack()
        if not spec.accepts(raw):
            return Fr700NakCode.DATA_RANGE
        self._parameters[number] = raw
        if number == 1:  # a lower maximum frequency pulls the set frequency down with it
            self._freq_ram = min(self._freq_ram, raw)
            self._freq_eeprom = min(self._freq_eeprom, raw)
        return self._ack()

    def _write_second_parameter(self, request: HostRequest, now: float) -> Result:
        value = int(request.data, 16)
        if value > 1:
            return Fr700NakCode.DATA_RANGE
        self._second_parameter = value
        return self._ack()

    def _write_frequency(self, request: HostRequest, now: float) -> Result:
        result = self._set_frequency(
            int(request.data, 16), request.instruction == I.WRITE_SET_FREQUENCY_EEPROM
        )
        return self._ack() if result is Fr700NakCode.NO_ERROR else result

    def _set_frequency(self, centi_hz: int, eeprom: bool) -> Fr700NakCode:
        if self._mode is not _NETWORK:
            return Fr700NakCode.MODE
        if centi_hz > self._parameters[1]:
            return Fr700NakCode.DATA_RANGE
        self._freq_ram = centi_hz
        if eeprom:
            self._freq_eeprom = centi_hz
        return Fr700NakCode.NO_ERROR

    def _multi_command(self, request: HostRequest, now: float) -> Result:
        send, receive = request.data[0] - 0x30, request.data[1] - 0x30
        if send not in (0, 1) or receive not in (0, 1, 2, 3):
            return Fr700NakCode.PROTOCOL
        run_error = self._set_run(int(request.data[2:6], 16))
        frequency_error = self._set_frequency(int(request.data[6:10], 16), send == 1)
        self._advance(now)
        monitor = self._special_monitor if receive == 3 else receive + 1
        data = b"%d%d%X%X%04X%04X" % (
            send,
            receive,
            run_error,
            frequency_error,
            self._status_bits(),
            self._monitor(monitor),
        )
        return Fr700Data(self.station, data)

    def _write_special_monitor_selection(self, request: HostRequest, now: float) -> Result:
        value = int(request.data, 16)
        if value not in _SPECIAL_MONITORS:
            return Fr700NakCode.DATA_RANGE
        self._special_monitor = value
        return self._ack()

    def _clear_fault_history(self, request: HostRequest, now: float) -> Result:
        if int(request.data, 16) != RESET_DATA:
            return Fr700NakCode.DATA_RANGE
        if self._mode is not _NETWORK:
            return Fr700NakCode.MODE
        self._faults.clear()
        return self._ack()

    def _run_command(self, request: HostRequest, now: float) -> Result:
        result = self._set_run(int(request.data, 16))
        return self._ack() if result is Fr700NakCode.NO_ERROR else result

    def _set_run(self, bits: int) -> Fr700NakCode:
        if self._mode is not _NETWORK:
            return Fr700NakCode.MODE
        if not self._tripped:  # a tripped drive acknowledges and ignores it
            self._run_bits = bits
        return Fr700NakCode.NO_ERROR

    def _write_operation_mode(self, request: HostRequest, now: float) -> Result:
        mode = Fr700OperationMode(int(request.data, 16))
        if not mode.known:
            return Fr700NakCode.DATA_RANGE
        if self._state().outputting:
            return Fr700NakCode.MODE
        self._mode = mode
        return self._ack()

    def _parameter_clear(self, request: HostRequest, now: float) -> Result:
        if int(request.data, 16) not in _CLEAR_CODES:
            return Fr700NakCode.DATA_RANGE
        if self._mode is not _NETWORK or self._state().outputting:
            return Fr700NakCode.MODE
        kept = {n: self._parameters[n] for n in COMMUNICATION}
        self._parameters = factory_values() | kept
        self._analog = dict(BIAS_GAIN_ANALOG)
        return self._ack()

    def _inverter_reset(self, request: HostRequest, now: float) -> Result:
        if int(request.data, 16) != RESET_DATA:
            return Fr700NakCode.DATA_RANGE
        self._restart()
        self._deaf_until = now + self.reset_s
        return None

    def _write_link_extension(self, request: HostRequest, now: float) -> Result:
        bank = int(request.data, 16)
        if bank > 9:
            return Fr700NakCode.DATA_RANGE
        self._bank = bank
        return self._ack()

    # -- the model ----------------------------------------------------------------------------

    def _start_mode(self) -> Fr700OperationMode:
        return _NETWORK if self._parameters[340] else Fr700OperationMode.EXTERNAL

    def _restart(self) -> None:
        self._tripped = False
        self._run_bits = 0
        self._output = Output()
        self._bank = 0
        self._mode = self._start_mode()
        self._freq_ram = self._freq_eeprom
        self.last_data_reply = None

    def _advance(self, now: float) -> None:
        """Bring the output to *now* along its ramps (time never runs backwards)."""
        if self._clock is None:
            self._clock = now
        dt = max(0.0, now - self._clock)
        self._clock += dt
        if self._tripped:
            self._output = Output()
            return
        self._output = advance(
            self._output, self._command(), self._freq_ram / 100, self._ramp(), dt
        )

    def _command(self) -> Direction:
        forward = bool(self._run_bits & _FORWARD_BIT)
        reverse = bool(self._run_bits & _REVERSE_BIT)
        if forward == reverse or self._tripped:
            return Direction.STOP
        return Direction.FORWARD if forward else Direction.REVERSE

    def _ramp(self) -> Ramp:
        reference_hz = self._parameters[20] / 100
        accel_s, decel_s = self._parameters[7] / 10, self._parameters[8] / 10
        return Ramp(
            reference_hz / accel_s if accel_s else math.inf,
            reference_hz / decel_s if decel_s else math.inf,
        )

    def _state(self) -> RunState:
        return classify(
            self._output,
            self._command(),
            self._freq_ram / 100,
            tripped=self._tripped,
            free_run=False,
        )

    def _status_bits(self) -> Fr700StatusBits:
        return status_bits(self._state(), self._output, self._parameters[42], self._tripped)

    def _monitor(self, selection: int) -> int:
        return monitor(selection, self._state(), self._output, self._freq_ram, self._parameters)


_HANDLERS: Final[dict[int, Handler]] = {
    I.READ_SECOND_PARAMETER: Fr700SimulatedDrive._read_second_parameter,
    I.READ_SET_FREQUENCY_RAM: Fr700SimulatedDrive._read_frequency_ram,
    I.READ_SET_FREQUENCY_EEPROM: Fr700SimulatedDrive._read_frequency_eeprom,
    I.OUTPUT_FREQUENCY: Fr700SimulatedDrive._read_output_frequency,
    I.OUTPUT_CURRENT: Fr700SimulatedDrive._read_output_current,
    I.OUTPUT_VOLTAGE: Fr700SimulatedDrive._read_output_voltage,
    I.READ_SPECIAL_MONITOR_SELECTION: Fr700SimulatedDrive._read_special_monitor_selection,
    **dict.fromkeys(range(116, 120), Fr700SimulatedDrive._read_fault_history),
    I.EXTENDED_STATUS: Fr700SimulatedDrive._read_extended_status,
    I.STATUS: Fr700SimulatedDrive._read_status,
    I.READ_OPERATION_MODE: Fr700SimulatedDrive._read_operation_mode,
    I.READ_LINK_EXTENSION: Fr700SimulatedDrive._read_link_extension,
    I.WRITE_SECOND_PARAMETER: Fr700SimulatedDrive._write_second_parameter,
    I.WRITE_SET_FREQUENCY_RAM: Fr700SimulatedDrive._write_frequency,
    I.WRITE_SET_FREQUENCY_EEPROM: Fr700SimulatedDrive._write_frequency,
    I.MULTI_COMMAND: Fr700SimulatedDrive._multi_command,
    I.WRITE_SPECIAL_MONITOR_SELECTION: Fr700SimulatedDrive._write_special_monitor_selection,
    I.CLEAR_FAULT_HISTORY: Fr700SimulatedDrive._clear_fault_history,
    I.EXTENDED_RUN_COMMAND: Fr700SimulatedDrive._run_command,
    I.RUN_COMMAND: Fr700SimulatedDrive._run_command,
    I.WRITE_OPERATION_MODE: Fr700SimulatedDrive._write_operation_mode,
    I.PARAMETER_CLEAR: Fr700SimulatedDrive._parameter_clear,
    I.INVERTER_RESET: Fr700SimulatedDrive._inverter_reset,
    I.WRITE_LINK_EXTENSION: Fr700SimulatedDrive._write_link_extension,
}
