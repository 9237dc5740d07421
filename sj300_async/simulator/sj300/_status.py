"""From run state to the manual's status codes: command 04's A/B/C and a trip record's A/C.

Decisions (the manual lists the codes, not when each applies):

- Status A "on running" (03) whenever the inverter outputs, including the
  deceleration after a stop command; "on stopping" (02) when it does not.
  "Initial status" (00) is the drive's power-up instant, which a simulated
  drive passes in no time, so it is never reported.
- Status C names what the output does, and uses its direction codes where
  they say more: "forward / reverse start" (09 / 10) at the instant a run
  command leaves 0 Hz, "reverse from forward" / "forward from reverse"
  (07 / 08) while ramping down through 0 Hz to reverse, and "forward /
  reverse" (05 / 06) while running at a 0 Hz setpoint.
- A trip record keeps the state *before* the trip: Status A running or
  stopping, and the trip-record Status C of what the output was doing.
"""

from __future__ import annotations

from typing import Final

from ...sj300.codec import InverterStatus, StatusA, StatusB, StatusC, TripStatusC
from ...wire import Direction
from .._motion import Output, RunState

__all__ = ["inverter_status", "trip_status_a", "trip_status_c"]

_STATUS_A: Final = {
    RunState.STOPPED: StatusA.STOPPING,
    RunState.ACCELERATING: StatusA.RUNNING,
    RunState.CONSTANT_SPEED: StatusA.RUNNING,
    RunState.DECELERATING: StatusA.RUNNING,
    RunState.FREE_RUN: StatusA.FREE_RUN_STOP,
    RunState.TRIPPED: StatusA.TRIP,
}

_STATUS_B: Final = {
    RunState.STOPPED: StatusB.STOPPED,
    RunState.ACCELERATING: StatusB.RUNNING,
    RunState.CONSTANT_SPEED: StatusB.RUNNING,
    RunState.DECELERATING: StatusB.RUNNING,
    RunState.FREE_RUN: StatusB.STOPPED,
    RunState.TRIPPED: StatusB.TRIPPED,
}

_TRIP_STATUS_C: Final = {
    RunState.STOPPED: TripStatusC.STOPPING,
    RunState.ACCELERATING: TripStatusC.ACCELERATING,
    RunState.CONSTANT_SPEED: TripStatusC.CONSTANT_SPEED,
    RunState.DECELERATING: TripStatusC.DECELERATING,
    RunState.FREE_RUN: TripStatusC.STOPPING,
    RunState.TRIPPED: TripStatusC.STOPPING,
}

_START = {Direction.FORWARD: StatusC.FORWARD_START, Direction.REVERSE: StatusC.REVERSE_START}
_TURNING = {Direction.FORWARD: StatusC.FORWARD, Direction.REVERSE: StatusC.REVERSE}
# Keyed by the commanded direction while the output still turns the other way.
_REVERSING = {
    Direction.REVERSE: StatusC.REVERSE_FROM_FORWARD,
    Direction.FORWARD: StatusC.FORWARD_FROM_REVERSE,
}


def _status_c(state: RunState, output: Output, command: Direction) -> StatusC:
    if state is RunState.ACCELERATING:
        return _START[output.direction] if output.hz == 0 else StatusC.ACCELERATING
    if state is RunState.DECELERATING:
        reversing = command is not Direction.STOP and output.direction is not command
        return _REVERSING[command] if reversing else StatusC.DECELERATING
    if state is RunState.CONSTANT_SPEED:
        return _TURNING[output.direction] if output.hz == 0 else StatusC.CONSTANT_SPEED
    return StatusC.STOP


def inverter_status(state: RunState, output: Output, command: Direction) -> InverterStatus:
    """Command 04's status A, B and C."""
    return InverterStatus(_STATUS_A[state], _STATUS_B[state], _status_c(state, output, command))


def trip_status_a(state: RunState) -> StatusA:
    """Status A as a trip record keeps it: the state just before the trip."""
    return _STATUS_A[state]


def trip_status_c(state: RunState, output: Output) -> TripStatusC:
    """A trip record's Status C: what the output was doing just before the trip."""
    if state is RunState.CONSTANT_SPEED and output.hz == 0:
        return TripStatusC.ZERO_HZ_RUN
    return _TRIP_STATUS_C[state]
