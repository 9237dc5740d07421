"""The run state machine of a simulated drive: where the output is heading, and how fast.

Every change of the output frequency and every run state lives in this
module: :func:`advance` moves the output along its ramps over a span of
time, :func:`classify` names the state the drive is in. The drive feeds
them its inputs (run command, setpoint, trip and free-run latches); the
only other change it makes to the output is cutting it to 0 Hz at once on
a trip or while FRS is on.

States (:class:`RunState`) and what puts the drive in them::

    state            when                                              leaves when
    STOPPED          no run command, output 0 Hz                        a run command
    ACCELERATING     output below its goal (includes the 0 Hz start)    goal reached / goal lowered
    CONSTANT_SPEED   output at the setpoint with a run command          setpoint or command changes
    DECELERATING     output above its goal: lower setpoint, stop        goal reached
                     command, or reversing down through 0 Hz
    FREE_RUN         FRS terminal on: output cut, the motor coasts      FRS off (restarts from 0 Hz)
    TRIPPED          a trip is latched: output cut                      RS terminal / power cycle

The goal is 0 Hz on a stop command, and also while the output still turns
the other way than commanded (a reversal ramps down through 0 Hz and then
up in the new direction); otherwise it is the setpoint. Ramp rates come
from F002 / F003, the times to ramp between 0 Hz and the maximum frequency
A004, as on the real drive.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from ..wire import Direction

__all__ = ["Output", "Ramp", "RunState", "advance", "classify", "goal_hz", "settled"]


class RunState(enum.Enum):
    """What a simulated drive is doing (see the module docstring for the transitions)."""

    STOPPED = "stopped"  #: no run command, no output
    ACCELERATING = "accelerating"  #: output rising toward the setpoint
    CONSTANT_SPEED = "constant speed"  #: output at the setpoint
    DECELERATING = "decelerating"  #: output falling toward the setpoint or 0 Hz
    FREE_RUN = "free-run"  #: FRS on: output cut, motor coasting
    TRIPPED = "tripped"  #: trip latched: output cut

    @property
    def outputting(self) -> bool:
        """True while the inverter drives the motor (the RUN signal)."""
        return self in _OUTPUTTING


_OUTPUTTING = frozenset({RunState.ACCELERATING, RunState.CONSTANT_SPEED, RunState.DECELERATING})


@dataclass(frozen=True, slots=True)
class Ramp:
    """Acceleration and deceleration rates, from F002 / F003 and A004."""

    up_hz_per_s: float
    down_hz_per_s: float

    @classmethod
    def from_times(cls, max_hz: float, accel_s: float, decel_s: float) -> Ramp:
        """Rates that take *accel_s* / *decel_s* seconds between 0 Hz and *max_hz*."""
        return cls(max_hz / accel_s, max_hz / decel_s)


@dataclass(frozen=True, slots=True)
class Output:
    """What the inverter puts out: frequency and phase sequence."""

    #: Output frequency, never negative.
    hz: float = 0.0
    #: Direction of rotation; STOP only when no run command holds the output at 0 Hz.
    direction: Direction = Direction.STOP


def goal_hz(output: Output, command: Direction, setpoint_hz: float) -> float:
    """Where the output is heading now: the setpoint, or 0 Hz (stop, or reversing)."""
    return _goal(output.hz, output.direction, command, setpoint_hz)


def _goal(hz: float, direction: Direction, command: Direction, setpoint_hz: float) -> float:
    # goal_hz() on the parts of an Output, so advance() need not build one per segment.
    if command is Direction.STOP:
        return 0.0
    if hz > 0 and direction is not command:
        return 0.0
    return setpoint_hz


def settled(output: Output, command: Direction, setpoint_hz: float) -> bool:
    """True when :func:`advance` leaves *output* as it is, however long the span.

    That is when it is at its goal and already turns the way :func:`advance`
    would set it: the commanded direction, or STOP when stopped.
    """
    return output.direction is command and output.hz == goal_hz(output, command, setpoint_hz)


def advance(
    output: Output, command: Direction, setpoint_hz: float, ramp: Ramp, dt_s: float
) -> Output:
    """The output *dt_s* seconds later, following the ramps toward the goal.

    With ``dt_s == 0`` it only applies what is instantaneous: taking the
    commanded direction at 0 Hz, or dropping it when stopped. An output
    that does not change is returned as it is (the same object).
    """
    hz, direction = output.hz, output.direction
    # At most three segments: down to 0 Hz, turn, up to the setpoint.
    while True:
        goal = _goal(hz, direction, command, setpoint_hz)
        if hz == 0 and command is not Direction.STOP:
            direction = command
        if hz == goal:
            break
        rate = ramp.up_hz_per_s if goal > hz else ramp.down_hz_per_s
        needed_s = abs(goal - hz) / rate
        if needed_s > dt_s:
            hz += math.copysign(rate * dt_s, goal - hz)
            break
        hz = goal  # exactly: a settled output reads the setpoint to the last digit
        dt_s -= needed_s
    if hz == 0 and command is Direction.STOP:
        direction = Direction.STOP
    if hz == output.hz and direction is output.direction:
        return output
    return Output(hz, direction)


def classify(
    output: Output,
    command: Direction,
    setpoint_hz: float,
    *,
    tripped: bool,
    free_run: bool,
) -> RunState:
    """The run state for these inputs (the one place that decides it)."""
    if tripped:
        return RunState.TRIPPED
    if free_run:
        return RunState.FREE_RUN
    if command is Direction.STOP and output.hz == 0:
        return RunState.STOPPED
    goal = goal_hz(output, command, setpoint_hz)
    if output.hz < goal:
        return RunState.ACCELERATING
    if output.hz > goal:
        return RunState.DECELERATING
    return RunState.CONSTANT_SPEED
