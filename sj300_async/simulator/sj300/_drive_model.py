"""The model inside a simulated SJ300: its inputs, its output, and what they make of each other.

:class:`DriveModel` holds a drive's inputs (the latches that the line and
outside events set, and the parameters in its memory) and its output, and
brings the output to any time along its ramps. From them it works out what
the replies report: the run state, command 04's status, command 03's
monitor block, and the record a trip leaves. What the drive does with each
command, and the decisions a real drive leaves open, are in :mod:`._drive`,
whose :class:`~._drive.SimulatedDrive` is this model with its faces (the
line, inspection, outside events).

The inputs change only at requests and events, while every request reads
the run state several times: what the inputs make of the output is kept in
a :class:`_Snapshot` until something changes (see
:meth:`DriveModel._changed`), and what the parameters give in
:class:`_Settings` until RAM is written.
"""

from __future__ import annotations

import logging
from typing import Final

from ...sj300.codec import (
    DataReply,
    InputMonitor,
    InputTerminal,
    InverterStatus,
    MonitorData,
    OutputTerminal,
    TripRecord,
    motor_capacity_kw,
)
from ...wire import Direction
from .._electrical import MotorRating, electrical
from .._motion import Output, Ramp, RunState, advance, classify, settled
from ._memory import ParameterMemory
from ._parameters_table import SOURCE_SERIAL, SOURCE_TERMINAL
from ._status import inverter_status, trip_status_a, trip_status_c
from ._trips import TripLog, trip_status_b

__all__ = ["DriveModel"]

_log = logging.getLogger("sj300_async.simulator")

_HOUR_S: Final = 3600.0

# Terminal bits as plain ints: IntFlag arithmetic runs enum's Python code on every
# operation, and the run command is worked out several times per request.
_FW: Final = InputTerminal.FW.value
_RV: Final = InputTerminal.RV.value
_FRS: Final = InputTerminal.FRS.value

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


class DriveModel:
    """One drive's inputs and output, and what they make of each other (see the module docstring).

    Args:
        node: the drive's address (checked by the drive).
        memory: its parameter memory, loaded with the values it starts with.
    """

    def __init__(self, node: int, memory: ParameterMemory) -> None:
        self.node = node
        self._memory = memory
        self._settings_cache = _Settings(memory)
        self._trips = TripLog()
        self._clock: float | None = None
        self._output = Output()
        # The latches: with the parameters, the model's inputs. Whatever changes one
        # (or the output, outside _advance) calls _changed().
        self._serial_run = Direction.STOP
        self._terminals = 0
        self._tripped = False
        self._snapshot_cache: _Snapshot | None = None
        self._run_s = 0.0
        self._power_on_s = 0.0

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
        """The run command the drive obeys, with A002 = *source* (see :mod:`._drive`)."""
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
