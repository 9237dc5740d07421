"""Plausible output current, voltage, torque and power for a simulated drive.

Not a motor model: a few deterministic formulas whose values move the way a
real drive's monitors do, so a display or a test sees sensible numbers and
can predict them exactly (no noise).

- Voltage follows the V/f line: rated voltage (A082) times f / base
  frequency (A003), capped at rated voltage above base frequency.
- Torque is a fan-like load, 20 % + 40 % x (f / base)^2, plus 60 % while
  accelerating; only 10 % while decelerating (the load helps braking).
- Current is 30 % magnetizing plus a torque-proportional part of the rated
  current (B012).
- Power is rated power (H003 in the B085 table) x torque x speed.

All are zero when the inverter does not output (stopped, free-run, tripped).
"""

from __future__ import annotations

from dataclasses import dataclass

from ._motion import RunState

__all__ = ["Electrical", "MotorRating", "electrical"]

_MAGNETIZING_SHARE = 0.3
_BASE_LOAD_PERCENT = 20.0
_SPEED_LOAD_PERCENT = 40.0
_ACCEL_EXTRA_PERCENT = 60.0
_DECEL_TORQUE_PERCENT = 10.0


@dataclass(frozen=True, slots=True)
class MotorRating:
    """The rating the electrical values scale with."""

    voltage_v: float  #: A082
    current_a: float  #: B012
    power_kw: float  #: H003 through the B085 capacity table
    base_hz: float  #: A003


@dataclass(frozen=True, slots=True)
class Electrical:
    """The monitored electrical values at one instant."""

    current_a: float
    voltage_v: float
    torque_percent: int
    power_kw: float


_OFF = Electrical(0.0, 0.0, 0, 0.0)


def electrical(state: RunState, hz: float, rating: MotorRating) -> Electrical:
    """The values a drive in *state* at *hz* shows."""
    if not state.outputting:
        return _OFF
    speed = hz / rating.base_hz
    if state is RunState.DECELERATING:
        torque = _DECEL_TORQUE_PERCENT
    else:
        torque = _BASE_LOAD_PERCENT + _SPEED_LOAD_PERCENT * speed * speed
        if state is RunState.ACCELERATING:
            torque += _ACCEL_EXTRA_PERCENT
    current = rating.current_a * (_MAGNETIZING_SHARE + (1 - _MAGNETIZING_SHARE) * torque / 100)
    return Electrical(
        current_a=round(current, 1),
        voltage_v=round(rating.voltage_v * min(1.0, speed), 1),
        torque_percent=round(torque),
        power_kw=round(rating.power_kw * torque / 100 * speed, 1),
    )
